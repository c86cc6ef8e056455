"""One interval definition for every table: a percentile bootstrap that resamples target instances.

Episodes of one target instance are correlated (the same object, often the same look-alikes),
so a resample draws instances with replacement and every episode of a drawn instance enters
together, as often as the instance is drawn; a frame-set with one episode per target
resamples episodes. One matcher's intervals (``bootstrap_ci``: a report's ``ci95``, the
verifier report's AUROC-same) and the paired differences (``paired.paired_comparison``) all
draw through ``episode_weights`` and reweight a ``Resampled`` matcher, so one seed gives one
set of resamples everywhere. Definitions: docs/metrics.md, "Confidence intervals".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from statistics import NormalDist

import numpy as np
import pandas as pd

from pin_match.evaluation.core.labels import CM, TM
from pin_match.evaluation.core.metrics import (
    COUNT_KEYS,
    DEFAULT_BOOT,
    METRIC_KEYS,
    Bootstrap,
    FrameArrays,
    Scored,
    as_arrays,
    episode_counts,
    ratios,
)

Clusters = Mapping[str, str]  # episode id -> its resampling unit (the target instance)
INTERVAL_KEYS = (*METRIC_KEYS, "auroc_target", "auroc_same")
EPISODE_SHARE_KEYS = ("match_pct", "first_match_success")  # of INTERVAL_KEYS, the % of episodes (a yes/no each)


def instance_clusters(episodes: pd.DataFrame) -> dict[str, str]:
    """Each episode's resampling unit: its target instance (from a frame-set's episodes table)."""
    return dict(zip(episodes.episode_id, episodes.target_object_id))


def unit_codes(episode_ids: Sequence[str], clusters: Clusters | None) -> np.ndarray:
    """Per episode, the code of its resampling unit (0 .. units - 1); without clusters each episode is one."""
    units = [clusters[e] for e in episode_ids] if clusters is not None else list(episode_ids)
    return pd.factorize(pd.Series(units, dtype=object))[0].astype(np.int64)


def episode_weights(codes: np.ndarray, boot: Bootstrap) -> Iterator[np.ndarray]:
    """Per resample, how often each episode enters: the number of times its unit was drawn."""
    n_units = int(codes.max()) + 1 if len(codes) else 0
    rng = np.random.default_rng(boot.seed)
    for _ in range(boot.n_boot):
        drawn = np.bincount(rng.integers(0, n_units, n_units), minlength=n_units).astype(np.float64)
        yield drawn[codes]


def per_episode_intervals(rows: pd.DataFrame, measure: Callable[[pd.DataFrame, np.ndarray | None], dict[str, float]],
                          clusters: Clusters | None, boot: Bootstrap,
                          shares: Collection[str] = ()) -> tuple[dict[str, float], dict]:
    """A per-episode table's measures (``measure(rows, weights)``, each episode counted ``weights`` times; None:
    once) and their percentile intervals over resampled units (an interval None where every resample is
    undefined). ``shares`` names the measures that are the % of episodes with a yes/no outcome (SR, CE, ...), whose
    interval at 0 % or 100 % is Wilson's (``intervals_of``)."""
    point = measure(rows, None)
    codes = unit_codes(list(rows["episode_id"]), clusters)
    drawn = [measure(rows, w) for w in episode_weights(codes, boot)] if len(rows) else []
    return point, intervals_of(point, drawn, codes, boot.level, shares)


def intervals_of(point: Mapping[str, float], drawn: Sequence[Mapping[str, float]], codes: np.ndarray, level: float,
                 shares: Collection[str]) -> dict[str, list[float] | None]:
    """Each measure's interval from its resampled values ``drawn``: the percentile one, but for a share of
    episodes (``shares``) every unit agrees on (0 % or 100 %), where each resample repeats the point and the
    percentile interval would be the point itself (0 of 4 episodes, "95 % CI 0-0 %"): there Wilson's over the
    units (``wilson_interval``)."""
    units = int(codes.max()) + 1 if len(codes) else 0
    out: dict[str, list[float] | None] = {}
    for key in point:
        if key in shares and point[key] in (0.0, 100.0):
            low, high = (100 * b for b in wilson_interval(round(point[key] / 100 * units), units, level))
        else:
            low, high = percentile_interval(np.array([d[key] for d in drawn]), level) if drawn else (math.nan,) * 2
        out[key] = None if math.isnan(low) else [low, high]
    return out


def wilson_interval(successes: int, n: int, level: float) -> tuple[float, float]:
    """Wilson's score interval of a share of ``successes`` in ``n`` trials (0-1; NaN for none): it stays inside
    0-1 and keeps a width at 0 of n and n of n (0 of 4 at 95 %: 0-0.49)."""
    if n <= 0:
        return math.nan, math.nan
    z = NormalDist().inv_cdf(0.5 + level / 2)
    p, z2 = successes / n, z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def percentile_interval(values: np.ndarray, level: float) -> tuple[float, float]:
    """The central ``level`` percentile interval of resampled values, undefined ones (NaN) left out;
    (NaN, NaN) when every resample is undefined."""
    values = np.asarray(values, np.float64)
    values = values[~np.isnan(values)]
    if not values.size:
        return math.nan, math.nan
    alpha = (1.0 - level) / 2.0 * 100.0
    return float(np.percentile(values, alpha)), float(np.percentile(values, 100.0 - alpha))


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


class Resampled:
    """One matcher's per-episode counts and score ranks at its sigma: what every resample reweights."""

    def __init__(self, arr: FrameArrays, sigma: float) -> None:
        counts = episode_counts(arr, sigma)
        self.matrix = np.stack([counts[k] for k in COUNT_KEYS], axis=1)
        self.first_tm = counts["n_first_tm"].astype(bool)
        values, self.inverse = np.unique(arr.score, return_inverse=True)
        self.n_values = len(values)
        self.episode = arr.episode
        self.target = (arr.cls == TM).astype(np.float64)
        self.same = (arr.cls == CM).astype(np.float64)

    def metrics(self, weights: np.ndarray) -> dict[str, float]:
        """Every metric of ``INTERVAL_KEYS`` with each episode counted ``weights`` times (ones: the point value)."""
        sums = weights @ self.matrix
        out = {k: float(v) for k, v in ratios(dict(zip(COUNT_KEYS, sums))).items()}
        w = weights[self.episode]
        out["auroc_target"] = weighted_auroc(self.inverse, self.n_values, self.target, 1.0 - self.target, w)
        out["auroc_same"] = weighted_auroc(self.inverse, self.n_values, self.target, self.same, w)
        return out


def bootstrap_ci(scored: Scored, sigma: float, *, clusters: Clusters | None = None,
                 boot: Bootstrap = DEFAULT_BOOT) -> dict[str, list[float] | None]:
    """Percentile intervals of ``INTERVAL_KEYS`` at ``sigma``, resampling ``clusters``' units (target instances).

    ``clusters``: ``instance_clusters(fs.episodes)``; None resamples episodes. Resamples where a
    metric is undefined are left out of its interval; a metric undefined in every resample has
    no interval (None).
    """
    arr = as_arrays(scored)
    side = Resampled(arr, sigma)
    codes = unit_codes(arr.episode_ids, clusters)
    point = side.metrics(np.ones(len(arr.episode_ids)))
    drawn = [side.metrics(w) for w in episode_weights(codes, boot)]
    return intervals_of({k: point[k] for k in INTERVAL_KEYS}, drawn, codes, boot.level, EPISODE_SHARE_KEYS)
