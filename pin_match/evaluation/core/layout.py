"""Where a bench folder (what ``bench`` and ``pin-match demo`` write) keeps each file: one object, asked by all.

``bench`` writes through it, ``analysis.load_bench`` and ``compare_bench`` read through it and
``index_page`` finds the pages through it, so a file is named in one place; one report folder's
files, by name, are ``ReportFiles`` (``report`` writes them, ``report_page`` shows the plots).
The demo nests a second bench folder (the real look-alikes) inside the first: ``BenchLayout.nested``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

REPORT_PAGE = "report.html"
METRICS = "metrics.json"
COMPARE_PAGE = "compare.html"


@dataclass(frozen=True)
class CompareFolder:
    """One paired comparison's files: the table as CSV and Markdown, the page and its images."""

    root: Path

    @property
    def csv(self) -> Path:
        return self.root / "compare.csv"

    @property
    def markdown(self) -> Path:
        return self.root / "compare.md"

    @property
    def page(self) -> Path:
        return self.root / COMPARE_PAGE


@dataclass(frozen=True)
class ReportFiles:
    """One matcher's report folder at one sigma, each file by name: ``report`` writes them, the page shows the plots."""

    metrics: Path  # metrics.json, written last: a report folder without one is a report that stopped
    per_category: Path
    markdown: Path
    latex: Path
    sigma_curves: Path
    score_distributions: Path
    per_category_plot: Path
    navigation: Path  # each episode's stop (``navigation.episodes_at``); written where the frame-set has geometry
    navigation_curves: Path
    sizes: Path  # the figures per band of the objects' pixel area (``sizes.size_table``)
    views: Path  # frames per reference view their best box matched (``views.view_table``); where the matcher names any
    commits: Path  # what the stop policy committed to per episode (``commits.commitments``); for a policy but PIN's
    page: Path

    @classmethod
    def in_folder(cls, folder: str | Path) -> ReportFiles:
        folder = Path(folder)
        return cls(metrics=folder / METRICS, per_category=folder / "per_category.csv", markdown=folder / "metrics.md",
                   latex=folder / "metrics.tex", sigma_curves=folder / "sigma_curves.png",
                   score_distributions=folder / "score_distributions.png",
                   per_category_plot=folder / "per_category.png", navigation=folder / "navigation.csv",
                   navigation_curves=folder / "navigation_curves.png", sizes=folder / "sizes.csv",
                   views=folder / "views.csv", commits=folder / "commits.csv", page=folder / REPORT_PAGE)


@dataclass(frozen=True)
class BenchLayout:
    """The files of one bench folder, by matcher name."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def frameset(self) -> Path:
        """Where the demo keeps the frame-set it built (``load_bench``'s default frame-set)."""
        return self.root / "frameset"

    @property
    def scores(self) -> Path:
        """The score cache (``scoring.cache.cache_dir`` under it)."""
        return self.root / "scores"

    def thresholds(self, matcher: str) -> Path:
        """The tuned sigma (absent when sigma was not tuned)."""
        return self.root / "thresholds" / f"{matcher}.json"

    def report(self, matcher: str) -> Path:
        return self.root / "reports" / matcher

    def report_metrics(self) -> list[Path]:
        """Every report's ``metrics.json`` (written last, so a report that stopped has none), sorted by matcher."""
        return sorted((self.root / "reports").glob(f"*/{METRICS}"))

    def report_page(self, matcher: str) -> Path:
        return ReportFiles.in_folder(self.report(matcher)).page

    def compare(self, first: str, other: str) -> CompareFolder:
        """``other`` against ``first`` (the differences are other minus first)."""
        return CompareFolder(self.root / "compare" / f"{other}_vs_{first}")

    def table(self, suffix: str) -> Path:
        """The side-by-side table as ``md``, ``tex`` or ``csv``."""
        return self.root / f"table.{suffix}"

    @property
    def index(self) -> Path:
        return self.root / "index.html"

    def nested(self, name: str) -> BenchLayout:
        """A second bench folder inside this one (the demo's real look-alikes)."""
        return BenchLayout(self.root / name)
