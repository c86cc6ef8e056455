"""pin-match inspect: the frame-set page flags failed cut-outs and shows every object, counts and sample frames."""

from __future__ import annotations

import re

import numpy as np

from pin_match.cli.main import main
from pin_match.evaluation.pages.frameset_page import counts, cutout_problems


def _view(opaque_fraction: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    view = rng.integers(0, 255, (50, 40, 4), dtype=np.uint8)
    view[..., 3] = 0
    view.reshape(-1, 4)[: int(opaque_fraction * 2000), 3] = 255
    return view


def test_cutout_problems_name_what_is_wrong():
    good = (_view(0.5, 0), _view(0.5, 1), _view(0.5, 2))
    assert cutout_problems(good) == []
    photo = (_view(1.0, 0), _view(0.5, 1), _view(0.5, 2))
    assert cutout_problems(photo) == ["view 0 is not cut out (100% opaque)"]
    empty = (_view(0.5, 0), _view(0.0, 1), _view(0.5, 2))
    assert cutout_problems(empty) == ["view 1 is almost empty (0.0% opaque)"]
    assert cutout_problems((good[0],) * 3) == ["the 3 views are one image repeated"]


def test_counts_per_split_and_category(tiny_frameset):
    table = counts(tiny_frameset)
    assert table.loc["val / mug", "objects"] == 2 and table.loc["val / ball", "objects"] == 1
    assert table.loc["val / mug", "episodes"] == 1 and table.loc["val / ball", "episodes"] == 0
    row = table.loc["train / mug"]
    assert [row[f"frames: {r}"] for r in ("target", "same-category look-alike", "other", "nothing")] == [1, 1, 1, 1]


def test_inspect_command_writes_the_page(tiny_frameset, tmp_path, capsys):
    assert main(["inspect", str(tiny_frameset.root), "--out", str(tmp_path), "--per-role", "1"]) == 0
    page = tmp_path / "index.html"
    assert capsys.readouterr().out.strip() == str(page)
    text = page.read_text(encoding="utf-8")
    for oid in tiny_frameset.objects.object_id:
        assert f"{oid} (" in text
    # the tiny set repeats one image as its three views: every object is flagged
    assert text.count("the 3 views are one image repeated") == len(tiny_frameset.objects)
    assert text.count('<figure class="miss">') == len(tiny_frameset.objects)
    sources = re.findall(r'<img src="([^"]+)"', text)
    assert len(sources) == 3 * len(tiny_frameset.objects) + 4  # references + one frame per role
    assert all((tmp_path / s).is_file() for s in sources)
