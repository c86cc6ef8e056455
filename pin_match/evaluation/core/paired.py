"""Paired comparison of two matchers on the same frames: metric differences with clustered bootstrap intervals.

Two per-matcher intervals that overlap can hide a consistent gain, because both matchers
saw the same episodes. Here every bootstrap resample draws one set of *target instances*
(all episodes of a drawn instance enter together, as often as it is drawn) and computes
both matchers' metrics on it, so the interval is that of the difference. Episodes of one
instance are correlated (same object, often the same look-alikes), hence the clusters; a
frame-set with one episode per target reduces to resampling episodes: the resampling of
``intervals``, which every interval shares. Definitions: docs/metrics.md, "Paired comparison".
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pandas as pd

from pin_match.errors import PinMatchError
from pin_match.evaluation.core.intervals import Resampled, episode_weights, percentile_interval, unit_codes
from pin_match.evaluation.core.metrics import DEFAULT_BOOT, Bootstrap, FrameArrays, frame_arrays

COMPARED = (("auroc_target", "AUROC"), ("auroc_same", "AUROC-same"), ("tm_pct", "TM"), ("cm_pct", "CM"),
            ("match_pct", "%Match"), ("first_match_precision", "FM-prec"))


class PairedError(PinMatchError, ValueError):
    """Two score tables that cannot be compared frame by frame."""


def align(scored_a: pd.DataFrame, scored_b: pd.DataFrame, names: tuple[str, str] = ("A", "B")) -> pd.DataFrame:
    """One table of the frames both scored, with ``score_a`` and ``score_b``; refuses different frame lists."""
    only_a = set(scored_a.frame_id) - set(scored_b.frame_id)
    only_b = set(scored_b.frame_id) - set(scored_a.frame_id)
    if only_a or only_b:
        side, frames = (names[0], only_a) if only_a else (names[1], only_b)
        raise PairedError(f"{side} scored {len(frames)} frames the other did not (e.g. {sorted(frames)[0]!r}): "
                          "compare tables of the same frame-set and split")
    both = scored_a.merge(scored_b[["frame_id", "score"]], on="frame_id", suffixes=("_a", "_b"), validate="1:1")
    return both.sort_values(["episode_id", "step"]).reset_index(drop=True)


def _arrays(both: pd.DataFrame, side: str) -> FrameArrays:
    return frame_arrays(both.assign(score=both[f"score_{side}"]))


def paired_comparison(scored_a: pd.DataFrame, scored_b: pd.DataFrame, sigma_a: float, sigma_b: float, *,
                      clusters: Mapping[str, str] | None = None, names: tuple[str, str] = ("A", "B"),
                      boot: Bootstrap = DEFAULT_BOOT) -> pd.DataFrame:
    """Each metric of A and B, B - A, and its paired bootstrap interval; rows = metrics.

    ``clusters`` maps episode id to its resampling unit (the target instance); None: each
    episode is its own. Resamples where a difference is undefined are left out of its interval.
    """
    both = align(scored_a, scored_b, names)
    arr = _arrays(both, "a")
    a, b = Resampled(arr, sigma_a), Resampled(_arrays(both, "b"), sigma_b)
    codes = unit_codes(arr.episode_ids, clusters)
    ones = np.ones(arr.n_episodes)
    point_a, point_b = a.metrics(ones), b.metrics(ones)
    diffs = {key: np.empty(boot.n_boot) for key, _ in COMPARED}
    for i, weights in enumerate(episode_weights(codes, boot)):
        ma, mb = a.metrics(weights), b.metrics(weights)
        for key, _ in COMPARED:
            diffs[key][i] = mb[key] - ma[key]
    rows = {}
    for key, header in COMPARED:
        low, high = percentile_interval(diffs[key], boot.level)
        rows[header] = {names[0]: point_a[key], names[1]: point_b[key],
                        f"{names[1]} - {names[0]}": point_b[key] - point_a[key], "CI low": low, "CI high": high}
    table = pd.DataFrame.from_dict(rows, orient="index").rename_axis("Metric")
    n_units = int(codes.max()) + 1 if len(codes) else 0
    table.attrs.update(n_episodes=arr.n_episodes, n_units=n_units, n_boot=boot.n_boot, level=boot.level)
    return table


def mcnemar(first_a: np.ndarray, first_b: np.ndarray) -> dict[str, float | int]:
    """Exact McNemar test on paired per-episode outcomes ("the first match is the target"), two-sided."""
    a, b = np.asarray(first_a, bool), np.asarray(first_b, bool)
    only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
    n = only_a + only_b
    tail = sum(math.comb(n, k) for k in range(min(only_a, only_b) + 1)) / 2.0 ** n if n else 1.0
    return dict(only_a=only_a, only_b=only_b, both=int(np.sum(a & b)), neither=int(np.sum(~a & ~b)),
                p_value=min(1.0, 2.0 * tail))


def first_match_outcomes(scored_a: pd.DataFrame, scored_b: pd.DataFrame, sigma_a: float,
                         sigma_b: float) -> tuple[np.ndarray, np.ndarray]:
    """Per episode (same order for both): is each matcher's first frame at or above its sigma the target?"""
    both = align(scored_a, scored_b)
    return (Resampled(_arrays(both, "a"), sigma_a).first_tm, Resampled(_arrays(both, "b"), sigma_b).first_tm)


def disagreements(scored_a: pd.DataFrame, scored_b: pd.DataFrame, sigma_a: float, sigma_b: float,
                  cap: int = 12) -> pd.DataFrame:
    """Frames one matcher accepts and the other rejects, the largest gap in score percentile first."""
    both = align(scored_a, scored_b)
    rank_a, rank_b = both.score_a.rank(pct=True), both.score_b.rank(pct=True)
    differ = (both.score_a >= sigma_a) != (both.score_b >= sigma_b)
    out = both.assign(rank_gap=(rank_b - rank_a).abs())[differ]
    return out.sort_values(["rank_gap", "frame_id"], ascending=[False, True]).head(cap).reset_index(drop=True)
