"""Load a finished bench folder (what ``bench`` / ``pin-match demo`` wrote) for analysis, e.g. the notebooks.

A bench folder (``layout.BenchLayout``) holds the score cache, the tuned thresholds and a report
per matcher; ``load_bench`` finds
each matcher's score table through its report (matcher id and frame-set fingerprint), so
a stale table of another config or frame-set in the same folder is never picked up.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.layout import BenchLayout
from pin_match.evaluation.core.tables import report_row, side_by_side
from pin_match.scoring.cache import cache_dir
from pin_match.scoring.table import ScoreTable


class AnalysisError(PinMatchError, ValueError):
    """A bench folder is incomplete or does not belong to the given frame-set."""


@dataclass
class BenchRun:
    layout: BenchLayout
    context: EvalContext                 # the frame-set and its labels
    tables: dict[str, ScoreTable]        # by matcher name, in the order of the reports
    sigmas: dict[str, float]             # the sigma each matcher was reported at (source: its report)
    reports: dict[str, dict]             # reports/<matcher>/metrics.json
    tuned: dict[str, dict]               # thresholds/<matcher>.json (absent unless bench tuned sigma)

    @property
    def root(self) -> Path:
        return self.layout.root

    @property
    def frameset(self) -> FrameSet:
        return self.context.fs

    @property
    def labels(self) -> pd.DataFrame:
        """``frame_labels(frameset)``, built once."""
        return self.context.labels

    @property
    def matchers(self) -> list[str]:
        return list(self.tables)

    def scored(self, matcher: str, split: str | None = None) -> pd.DataFrame:
        """The frame labels of the scored frames with their score (one split, or all for None / "all")."""
        return self.context.scored(self.tables[matcher], split)

    def table(self) -> pd.DataFrame:
        """The side-by-side table of the reports (rows = matchers), as ``bench`` wrote it."""
        return side_by_side([report_row(r) for r in self.reports.values()])


def load_bench(run_dir: str | Path | BenchLayout,
               frameset: FrameSet | str | Path | EvalContext | None = None) -> BenchRun:
    """Every matcher reported under ``run_dir`` with its score table and sigma (frame-set default: run_dir/frameset).

    ``frameset`` may be the run's ``EvalContext``, whose labels are then reused.
    """
    layout = run_dir if isinstance(run_dir, BenchLayout) else BenchLayout(Path(run_dir))
    ctx = EvalContext.of(layout.frameset if frameset is None else frameset)
    fs = ctx.fs
    report_files = layout.report_metrics()
    if not report_files:
        raise AnalysisError(f"no reports under {layout.root / 'reports'}: run `pin-match bench` or "
                            "`pin-match demo` first")
    tables, sigmas, reports = {}, {}, {}
    for path in report_files:
        report = atomic.read_json(path, AnalysisError, "report")
        name, matcher_id = report["matcher"], report["matcher_id"]
        if report.get("frameset_fingerprint") != fs.fingerprint:
            raise AnalysisError(f"{path} reports frame-set {report.get('frameset_fingerprint')}, "
                                f"not {fs.root} ({fs.fingerprint})")
        folder = cache_dir(layout.scores, matcher_id, fs.fingerprint)
        if not folder.is_dir():
            raise AnalysisError(f"{path} reports {matcher_id}, but there is no score table under {folder}")
        tables[name] = ScoreTable.read(folder)
        sigmas[name] = float(report["sigma"])  # where it came from: report["sigma_source"]
        reports[name] = report
    return BenchRun(layout, ctx, tables, sigmas, reports, tuned_thresholds(layout, list(tables)))


def tuned_thresholds(layout: BenchLayout, matchers: list[str]) -> dict[str, dict]:
    """The thresholds files of the matchers whose sigma the bench tuned (the others have none)."""
    files = {name: layout.thresholds(name) for name in matchers}
    return {name: atomic.read_json(path, AnalysisError, "thresholds file") for name, path in files.items()
            if path.exists()}
