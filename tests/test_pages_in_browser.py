"""A real browser opens report.html and inspect's page: every image loads and the screenshot is not blank.

Headless Chromium (Debian: ``apt-get install -y chromium``; ``.ci/run`` installs it when
missing). The check page is a copy of the page under test with one small script that, once
everything has loaded, writes into the title how many ``<img>`` have no pixels
(``naturalWidth == 0``); ``--dump-dom`` prints that title. Set PIN_MATCH_SCREENSHOTS to a folder
to keep the screenshots (the README's is docs/img/report.png).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_report_page import SIGMA, make_table

from pin_match.evaluation import Bootstrap, EvalContext
from pin_match.evaluation.flows.report import report
from pin_match.evaluation.pages.frameset_page import write_frameset_page

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
PROBE = """<script>
window.addEventListener("load", () => {
  const images = Array.from(document.images);
  const broken = images.filter(i => !i.complete || i.naturalWidth === 0).map(i => i.getAttribute("src"));
  document.title = "IMAGES " + images.length + " BROKEN " + broken.length + " " + broken.join(",");
});
</script>
"""


@pytest.fixture(scope="module")
def browser() -> str:
    found = next((shutil.which(b) for b in BROWSERS if shutil.which(b)), None)
    if found is None:
        pytest.skip("no headless Chromium on this machine: install it with `apt-get install -y chromium` "
                    "(.ci/run does when it is missing)")
    return found


def run_browser(browser: str, *args: str) -> str:
    cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
           "--allow-file-access-from-files", "--virtual-time-budget=20000", *args]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def check_page(browser: str, page: Path, shot_name: str) -> None:
    probe = page.with_name(f"_probe_{page.name}")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"), encoding="utf-8")
    dom = run_browser(browser, "--dump-dom", probe.as_uri())
    verdict = re.search(r"<title>IMAGES (\d+) BROKEN (\d+)([^<]*)</title>", dom)
    assert verdict, f"the check script did not run in {page}"
    assert int(verdict.group(1)) > 0 and int(verdict.group(2)) == 0, f"images not loaded: {verdict.group(3)}"
    probe.unlink()

    shot = page.with_name(shot_name)
    run_browser(browser, "--window-size=1280,1600", f"--screenshot={shot}", page.as_uri())
    pixels = np.asarray(Image.open(shot).convert("RGB"), np.float32)
    assert pixels.shape[:2] == (1600, 1280)
    assert pixels.std() > 20 and len(np.unique(pixels.reshape(-1, 3), axis=0)) > 500, "blank screenshot"
    keep = os.environ.get("PIN_MATCH_SCREENSHOTS")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        shutil.copy(shot, Path(keep) / shot_name)


def test_report_page_loads_in_a_browser(browser, tiny_frameset, tmp_path):
    report(make_table(tiny_frameset), EvalContext(tiny_frameset, Bootstrap(n_boot=20)), tmp_path, sigma=SIGMA,
           split="all")
    check_page(browser, tmp_path / "report.html", "report.png")


def test_frameset_page_loads_in_a_browser(browser, tiny_frameset, tmp_path):
    page = write_frameset_page(tiny_frameset, tmp_path, per_role=2)
    check_page(browser, page, "inspect.png")


def test_demo_index_page_loads_in_a_browser(browser, tiny_frameset, tmp_path):
    """The demo's index.html (headline, paired comparison, each matcher's first match drawn, links) in the demo's
    order: the real look-alikes (``lookalikes/``) first, the scanned set (the demo folder itself) second; both
    sets are the tiny one here, so that nothing is rendered."""
    import shutil
    from dataclasses import replace

    from markupsafe import escape

    from pin_match.evaluation.flows.demo import LOOKALIKES, SCANNED, demo
    from pin_match.scoring import RunOptions

    def copy(out: Path, seed: int, run: RunOptions, val_only: bool):
        shutil.copytree(tiny_frameset.root, out)
        return type(tiny_frameset).load(out)

    sets = [replace(LOOKALIKES, build=copy, matchers=("color",)),
            replace(SCANNED, build=copy, matchers=("color", "sift"))]
    results = demo(tmp_path / "demo", sets, run=RunOptions(workers=1, progress=False))
    assert [r.name for r in results] == ["look-alikes", "scanned look-alikes"]
    assert [len(r.comparisons) for r in results] == [0, 1]
    index = tmp_path / "demo" / "index.html"
    text = index.read_text(encoding="utf-8")
    assert text.index(escape(LOOKALIKES.caption)) < text.index(escape(SCANNED.caption))
    assert re.findall(r'<a href="([^"]+)"', text) == ["lookalikes/reports/color/report.html",
                                                       "reports/color/report.html", "reports/sift/report.html",
                                                       "compare/sift_vs_color/compare.html"]
    # issue 60.7: each set's first matches are one table row per val episode, one cell per matcher (no staggering)
    tables = re.findall(r'<table class="figures">.*?</table>', text, flags=re.S)
    assert [re.findall(r"<th>(.*?)</th>", t) for t in tables] == [["target", "color"], ["target", "color", "sift"]]
    for t, n_cells in zip(tables, (2, 3)):
        rows = re.findall(r"<tr>(.*?)</tr>", t.split("<tbody>")[1], flags=re.S)
        assert len(rows) == 1 and all(row.count("<td>") == n_cells for row in rows)  # the tiny set: 1 val episode
    check_page(browser, index, "index.png")
