"""Every page pin_match writes, fed names that break naive HTML: the text comes back unchanged, every link resolves.

The frame-set's category, object ids and episode ids and two registered matchers' names hold
quotes, a ``<script>`` tag, an entity, ``#``, ``?``, ``%``, spaces and non-ASCII letters. The report, compare,
inspect and index pages are parsed with the standard library's HTML parser: no element but the
page's own comes out of a name, every name reads back as written, and every ``href`` / ``src``
(URL-unquoted) is a file beside the page. The Markdown tables keep their column count.
"""

from __future__ import annotations

from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np
import pytest

from conftest import make_view, paint
from pin_match import CropMatcher, MatchResult, Modality, register_matcher
from pin_match.evaluation import Bootstrap, EvalContext
from pin_match.evaluation.core.tables import markdown_table
from pin_match.evaluation.flows.index_page import EPISODES_SHOWN
from pin_match.scoring import RunOptions

# ids and matcher names become file names, so they hold no "/"; the category holds a whole script element
NASTY = "\"q\" 'a' <script>alert(1) <b #x ?y=1 %41 &amp & a|b ü"
CATEGORY = f"mug <script>alert(2)</script> {NASTY}"
OBJECTS = {f"mug A {NASTY}": ("train", (200, 30, 30)), f"mug B {NASTY}": ("train", (30, 30, 200)),
           f"mug C {NASTY}": ("val", (220, 120, 20)), f"mug D {NASTY}": ("val", (120, 20, 220))}
EPISODES = {f"ep #1 ü {NASTY}": ("train", f"mug A {NASTY}", f"mug B {NASTY}"),
            f"ep #2 ü {NASTY}": ("val", f"mug C {NASTY}", f"mug D {NASTY}")}
MATCHER_A = f"toy-red {NASTY}"
MATCHER_B = f"toy-bright {NASTY}"
PAGE_TAGS = {"html", "head", "meta", "title", "style", "body", "h1", "h2", "h3", "p", "a", "ul", "li", "dl", "dt",
             "dd", "table", "caption", "thead", "tbody", "tr", "th", "td", "img", "figure", "figcaption", "br", "div",
             "span"}


class ToyMatcher(CropMatcher):
    """A score from the crop's pixels alone (``crop_score``), the crop's centre as its point."""

    modality = Modality.VISUAL

    def _prepare(self, target):
        pass

    def _match_crops(self, crops):
        return [MatchResult(score=self.crop_score(c), points=[[c.shape[1] / 2, c.shape[0] / 2]]) for c in crops]


class RedMatcher(ToyMatcher):
    """The share of the crop's pixels that are red (the colour of no val target)."""

    default_sigma = 0.01

    @staticmethod
    def crop_score(crop: np.ndarray) -> float:
        return float(((crop[..., 0] > 150) & (crop[..., 2] < 100)).mean())


class BrightMatcher(ToyMatcher):
    """The crop's mean brightness in [0, 1]."""

    default_sigma = 0.4

    @staticmethod
    def crop_score(crop: np.ndarray) -> float:
        return float(crop.mean() / 255.0)


@pytest.fixture(scope="module")
def hostile_matchers():
    """Both toys registered for this module only: other tests list the registry and expect no such names."""
    from pin_match.contract import registry

    for name, cls in ((MATCHER_A, RedMatcher), (MATCHER_B, BrightMatcher)):
        register_matcher(name)(cls)
    yield
    for name in (MATCHER_A, MATCHER_B):
        registry._REGISTRY.pop(name)


@pytest.fixture(scope="module")
def hostile_frameset(tmp_path_factory):
    """2 episodes x 3 frames (target, look-alike, nothing) whose every name is hostile."""
    from pin_match.data.writer import FrameSetWriter

    w = FrameSetWriter(tmp_path_factory.mktemp("hostile") / "set", f"set {NASTY}")
    views = {}
    for oid, (split, color) in OBJECTS.items():
        views[oid] = make_view(color)
        w.add_object(oid, CATEGORY, split, [views[oid]] * 3, [f"{oid}, view {k}" for k in range(3)])
    for ep, (split, target, lookalike) in EPISODES.items():
        w.add_episode(ep, split, "scene0", target, [lookalike])
        roles = w.roles(ep)
        for step, oid in enumerate([target, lookalike, None]):
            image = np.full((320, 240, 3), 90, np.uint8)
            mask = np.zeros((320, 240), np.uint16)
            legend = {}
            if oid is not None:
                paint(image, mask, 1, views[oid], 60, 100)
                legend[1] = (oid, roles[oid])
            w.add_frame(ep, step, image, mask, legend, np.full((320, 240), 2.0, np.float32))
    return w.close()


class Page(HTMLParser):
    """A page's tags, text and links, as a browser would read them."""

    def __init__(self, path: Path) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: set[str] = set()
        self.links: list[str] = []
        self.chunks: list[str] = []
        self.feed(path.read_text(encoding="utf-8"))
        self.text = "".join(self.chunks)

    def handle_starttag(self, tag, attrs):
        self.tags.add(tag)
        for name, value in attrs:
            if name in ("href", "src"):
                self.links.append(value)
            if name == "alt":
                self.chunks.append(f" {value} ")

    def handle_data(self, data):
        self.chunks.append(data)


def check_page(path: Path, names: list[str]) -> Page:
    page = Page(path)
    assert page.tags <= PAGE_TAGS, f"{path.name}: tags from a name: {page.tags - PAGE_TAGS}"
    for name in names:
        assert name in page.text, f"{path.name} does not show {name!r} as written"
    for link in page.links:
        parts = urlsplit(link)
        assert not (parts.scheme or parts.netloc or parts.query or parts.fragment), f"{path.name}: {link!r}"
        assert (path.parent / unquote(parts.path)).is_file(), f"{path.name}: {link!r} does not resolve"
    return page


@pytest.fixture(scope="module")
def pages(hostile_matchers, hostile_frameset, tmp_path_factory):
    """bench (tuned on train) + compare + index, and inspect, all written for the hostile set."""
    from pin_match.evaluation.flows.bench import bench
    from pin_match.evaluation.flows.compare import compare_bench
    from pin_match.evaluation.flows.index_page import SetResults, write_index
    from pin_match.evaluation.pages.frameset_page import write_frameset_page

    out = tmp_path_factory.mktemp("pages")
    done = bench(EvalContext(hostile_frameset, Bootstrap(n_boot=20)), [MATCHER_A, MATCHER_B], out / "bench",
                 run=RunOptions(workers=1, progress=False))
    comparisons = compare_bench(done.run)
    index = write_index(out / "bench", [SetResults(f"set {NASTY}", f"caption {NASTY}", done, comparisons)])
    inspect = write_frameset_page(hostile_frameset, out / "inspect", per_role=2)
    return dict(done=done, index=index, inspect=inspect, compare=comparisons[0].folder.page,
                reports=[done.run.layout.report_page(m) for m in (MATCHER_A, MATCHER_B)])


def test_report_pages_show_hostile_names_and_resolve_every_link(pages):
    for path, matcher in zip(pages["reports"], (MATCHER_A, MATCHER_B)):
        page = check_page(path, [matcher, CATEGORY, f"ep #2 ü {NASTY}", f"mug C {NASTY}"])  # the val split
        assert sum(link.endswith(".jpg") for link in page.links) > 0


def test_compare_page_draws_both_matchers_frames_with_outlines(pages):
    page = check_page(pages["compare"], [MATCHER_A, MATCHER_B])
    assert sum(link.endswith(".jpg") for link in page.links) >= 2 and "Mask outlines" in page.text


def test_inspect_page_shows_hostile_names_and_resolves_every_link(pages):
    page = check_page(pages["inspect"], [CATEGORY, *OBJECTS, f"set {NASTY}"])
    assert sum(link.endswith(".png") for link in page.links) == 3 * len(OBJECTS)


def test_index_page_tells_the_story_and_links_every_page(pages):
    index = pages["index"]
    page = check_page(index, [f"set {NASTY}", f"caption {NASTY}", MATCHER_A, MATCHER_B, f"mug C {NASTY}"])
    linked = {(index.parent / unquote(link)).resolve() for link in page.links}
    assert {p.resolve() for p in [*pages["reports"], pages["compare"]]} <= linked
    assert "First match is the target" in page.text and f"{MATCHER_B} minus {MATCHER_A}" in page.text
    labels = pages["done"].run.labels
    val = labels[(labels.split == "val") & ~labels.approach].groupby("episode_id").target_pixels.max()
    assert f"The walks show the target in {int((val > 0).sum())} of {len(val)} val episodes" in page.text
    drawn = page.text.count("walk frames,") + page.text.count("never in view on the walk")
    assert drawn == min(len(val), EPISODES_SHOWN)


def test_markdown_tables_keep_their_columns(pages):
    for text in (pages["done"].run.layout.table("md").read_text(encoding="utf-8"),
                 markdown_table(pages["done"].joint)):
        rows = [line for line in text.splitlines() if line.startswith("|")]
        widths = {len(line.replace("\\|", "").split("|")) for line in rows}
        assert len(rows) == 4 and len(widths) == 1, rows
        assert MATCHER_A.replace("|", "\\|") in text
