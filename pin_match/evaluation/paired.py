"""Paired comparison of two matchers on the same frames: metric differences with clustered bootstrap intervals.

Two per-matcher intervals that overlap can hide a consistent gain, because both matchers
saw the same episodes. Here every bootstrap resample draws one set of *target instances*
(all episodes of a drawn instance enter together, as often as it is drawn) and computes
both matchers' metrics on it, so the interval is that of the difference. Episodes of one
instance are correlated (same object, often the same look-alikes), hence the clusters; a
frame-set with one episode per target reduces to resampling episodes. Definitions:
docs/metrics.md, "Paired comparison".
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pandas as pd

from pin_match.errors import PinMatchError
from pin_match.evaluation.metrics import (
    CM,
    COUNT_KEYS,
    DEFAULT_BOOT,
    TM,
    Bootstrap,
    FrameArrays,
    episode_counts,
    frame_arrays,
    ratios,
)

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


def weighted_auroc(inverse: np.ndarray, n_values: int, positive: np.ndarray, negative: np.ndarray,
                   weights: np.ndarray) -> float:
    """Mann-Whitney AUROC where each frame counts ``weights`` times (ties one half); ``inverse`` ranks the scores."""
    wp = np.bincount(inverse, weights * positive, minlength=n_values)
    wn = np.bincount(inverse, weights * negative, minlength=n_values)
    total_p, total_n = wp.sum(), wn.sum()
    if total_p == 0 or total_n == 0:
        return math.nan
    below = np.cumsum(wn) - wn
    return float(np.sum(wp * (below + 0.5 * wn)) / (total_p * total_n))


class _Side:
    """One matcher's per-episode counts and score ranks: what every resample reweights."""

    def __init__(self, arr: FrameArrays, sigma: float) -> None:
        counts = episode_counts(arr, sigma)
        self.matrix = np.stack([counts[k] for k in COUNT_KEYS], axis=1)
        self.first_tm = counts["n_first_tm"].astype(bool)
        values, self.inverse = np.unique(arr.score, return_inverse=True)
        self.n_values = len(values)
        self.episode = arr.episode
        self.target = (arr.cls == TM).astype(np.float64)
        self.same = (arr.cls == CM).astype(np.float64)

    def metrics(self, episode_weights: np.ndarray) -> dict[str, float]:
        sums = episode_weights @ self.matrix
        out = {k: float(v) for k, v in ratios(dict(zip(COUNT_KEYS, sums))).items()}
        w = episode_weights[self.episode]
        out["auroc_target"] = weighted_auroc(self.inverse, self.n_values, self.target, 1.0 - self.target, w)
        out["auroc_same"] = weighted_auroc(self.inverse, self.n_values, self.target, self.same, w)
        return out


def paired_comparison(scored_a: pd.DataFrame, scored_b: pd.DataFrame, sigma_a: float, sigma_b: float, *,
                      clusters: Mapping[str, str] | None = None, names: tuple[str, str] = ("A", "B"),
                      boot: Bootstrap = DEFAULT_BOOT) -> pd.DataFrame:
    """Each metric of A and B, B - A, and its paired bootstrap interval; rows = metrics.

    ``clusters`` maps episode id to its resampling unit (the target instance); None: each
    episode is its own. Resamples where a difference is undefined are left out of its interval.
    """
    both = align(scored_a, scored_b, names)
    arr = _arrays(both, "a")
    a, b = _Side(arr, sigma_a), _Side(_arrays(both, "b"), sigma_b)
    unit_of = [clusters[e] if clusters is not None else e for e in arr.episode_ids]
    unit_codes, units = pd.factorize(pd.Series(unit_of))
    ones = np.ones(arr.n_episodes)
    point_a, point_b = a.metrics(ones), b.metrics(ones)
    rng = np.random.default_rng(boot.seed)
    diffs = {key: np.empty(boot.n_boot) for key, _ in COMPARED}
    for i in range(boot.n_boot):
        drawn = np.bincount(rng.integers(0, len(units), len(units)), minlength=len(units)).astype(np.float64)
        weights = drawn[unit_codes]
        ma, mb = a.metrics(weights), b.metrics(weights)
        for key, _ in COMPARED:
            diffs[key][i] = mb[key] - ma[key]
    alpha = (1.0 - boot.level) / 2.0 * 100.0
    rows = {}
    for key, header in COMPARED:
        d = diffs[key][~np.isnan(diffs[key])]
        low, high = (np.percentile(d, alpha), np.percentile(d, 100.0 - alpha)) if d.size else (math.nan, math.nan)
        rows[header] = {names[0]: point_a[key], names[1]: point_b[key],
                        f"{names[1]} - {names[0]}": point_b[key] - point_a[key], "CI low": low, "CI high": high}
    table = pd.DataFrame.from_dict(rows, orient="index").rename_axis("Metric")
    table.attrs.update(n_episodes=arr.n_episodes, n_units=len(units), n_boot=boot.n_boot, level=boot.level)
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
    return (_Side(_arrays(both, "a"), sigma_a).first_tm, _Side(_arrays(both, "b"), sigma_b).first_tm)


def disagreements(scored_a: pd.DataFrame, scored_b: pd.DataFrame, sigma_a: float, sigma_b: float,
                  cap: int = 12) -> pd.DataFrame:
    """Frames one matcher accepts and the other rejects, the largest gap in score percentile first."""
    both = align(scored_a, scored_b)
    rank_a, rank_b = both.score_a.rank(pct=True), both.score_b.rank(pct=True)
    differ = (both.score_a >= sigma_a) != (both.score_b >= sigma_b)
    out = both.assign(rank_gap=(rank_b - rank_a).abs())[differ]
    return out.sort_values(["rank_gap", "frame_id"], ascending=[False, True]).head(cap).reset_index(drop=True)
