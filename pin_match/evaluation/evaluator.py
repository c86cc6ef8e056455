"""One matcher's detection metrics on one split at one sigma, from a score table and its frame-set.

``check_frameset`` is the single test that scores and frame-set belong together; ``tune``,
``evaluate`` and the CLI all call it, so a table is never read against another frame-set's
labels. A caller that evaluates several tables of one frame-set (``bench``) builds its
``frame_labels`` once and passes them in; one split's scored frames become ``FrameArrays``
once, and every metric of that split reads them.
"""

from __future__ import annotations

import datetime as dt

import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.evaluation.labels import frame_labels, localisation_hits, scored_frames
from pin_match.evaluation.metrics import (
    FrameArrays,
    bootstrap_ci,
    detection_metrics,
    frame_arrays,
    localisation_metrics,
    per_category,
)
from pin_match.evaluation.sigma import SigmaChoice, way_out
from pin_match.scoring.table import ScoreTable


class EvaluationError(PinMatchError, ValueError):
    """Scores, frame-set and split do not belong together."""


def check_frameset(table: ScoreTable, fs: FrameSet) -> None:
    """Refuse a score table computed on another frame-set (or one that does not say which)."""
    fingerprint = table.meta.get("frameset_fingerprint")
    if fingerprint != fs.fingerprint:
        raise EvaluationError(f"score table of {table.matcher_id} was computed on frame-set {fingerprint}, "
                              f"not on {fs.root} ({fs.fingerprint}): pass the frame-set it was scored on")


def split_frames(table: ScoreTable, fs: FrameSet, split: str | None,
                 labels: pd.DataFrame | None = None) -> pd.DataFrame:
    """The frame labels of one split's scored frames with their score; a missing split says how to go on.

    ``labels``: ``frame_labels(fs)`` when the caller already has them (built here otherwise).
    """
    check_frameset(table, fs)
    scored = scored_frames(frame_labels(fs) if labels is None else labels, table)
    if split not in (None, "all"):
        scored = scored[scored.split == split].reset_index(drop=True)
    if scored.empty:
        raise EvaluationError(way_out(table.matcher_id, str(split), sorted(set(table.frames.split))))
    return scored


def evaluate(table: ScoreTable, fs: FrameSet, sigma: SigmaChoice, split: str | None = "val", *,
             labels: pd.DataFrame | None = None, n_boot: int = 1000,
             seed: int = 0) -> tuple[dict, pd.DataFrame, pd.DataFrame, FrameArrays]:
    """Metrics (with CIs and localisation), the per-category table, and one split's scored frames as a table
    (the report page's galleries need its ids and visibility) and as the arrays the metrics and plots use."""
    scored = split_frames(table, fs, split, labels)
    arr = frame_arrays(scored)
    metrics = detection_metrics(arr, sigma.value)
    hits = localisation_hits(fs, table_subset(table, scored.frame_id), sigma.value)
    metrics.update(localisation_metrics(hits))
    result = dict(matcher=table.matcher, matcher_id=table.matcher_id, config_hash=table.meta.get("config_hash"),
                  modality=table.meta.get("modality"), frameset_fingerprint=fs.fingerprint, split=split or "all",
                  **sigma.as_dict(), metrics=metrics,
                  ci95=bootstrap_ci(arr, sigma.value, n_boot=n_boot, seed=seed), n_bootstrap=n_boot,
                  date=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))
    return result, per_category(arr, sigma.value), scored, arr


def table_subset(table: ScoreTable, frame_ids: pd.Series) -> ScoreTable:
    return ScoreTable(table.frames[table.frames.frame_id.isin(frame_ids)].reset_index(drop=True), table.meta)
