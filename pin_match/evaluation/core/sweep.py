"""Every threshold metric at every distinct score, in one pass.

Applying each candidate sigma to every frame costs O(frames x thresholds); here the
scores are ranked once and every count of ``metrics.COUNT_KEYS`` is a reverse cumulative
sum over the ranks, so the whole curve costs about one sort:

- frame counts per class: a histogram over (rank, class), summed from the top;
- matched episodes: each episode is matched from its max score down (a sorted search);
- first matches: in step order, only a frame scoring above every earlier frame of its
  episode (a "record") can be the first matched one, and records' scores increase with
  step. Lowering sigma past a record's score makes it the first match, replacing the
  next (later, higher) record, so each record contributes "is TM" minus "next record is
  TM" at its rank, and the reverse cumsum of those deltas is the count at every sigma.

``sweep_loop`` is the plain per-threshold reference, for tests (exact equality) and the
benchmark's speed ratio.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from pin_match.evaluation.core.metrics import (
    CM,
    COUNT_KEYS,
    GM,
    METRIC_KEYS,
    OM,
    TM,
    FrameArrays,
    ratios,
    threshold_metrics,
)


def _from_top(per_rank: np.ndarray) -> np.ndarray:
    """Counts per ascending rank -> counts of everything at or above each rank."""
    return per_rank[::-1].cumsum(axis=0)[::-1]


def sweep_counts(arr: FrameArrays) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The distinct scores (ascending) and every count at sigma = each of them."""
    values, rank = np.unique(arr.score, return_inverse=True)
    k, n = len(values), arr.n_episodes
    if k == 0:
        return values, {name: np.zeros(0) for name in COUNT_KEYS}
    by_class = _from_top(np.bincount(rank * 4 + arr.cls, minlength=4 * k).reshape(k, 4))
    seen_matched = _from_top(np.bincount(rank[arr.seen == 1], minlength=k))

    starts = np.flatnonzero(np.r_[True, arr.episode[1:] != arr.episode[:-1]])
    episode_max = np.sort(np.maximum.reduceat(arr.score, starts))
    matched_episodes = n - np.searchsorted(episode_max, values, side="left")

    key = arr.episode * k + rank  # episode dominates, so the running max restarts at each episode
    running = np.maximum.accumulate(key)
    records = np.flatnonzero(np.r_[True, key[1:] > running[:-1]])
    is_tm = (arr.cls[records] == TM).astype(np.int64)
    same_episode_next = np.r_[arr.episode[records[1:]] == arr.episode[records[:-1]], False]
    next_tm = np.where(same_episode_next, np.r_[is_tm[1:], 0], 0)
    first_tm = _from_top(np.bincount(rank[records], weights=is_tm - next_tm, minlength=k))

    total_seen = float(np.count_nonzero(arr.seen == 1)) if arr.seen_known else np.nan
    counts = dict(
        n_episodes=np.full(k, float(n)), n_matched_episodes=matched_episodes.astype(np.float64),
        n_first_tm=np.rint(first_tm), n_frames=np.full(k, float(len(arr.score))),
        n_matched=by_class.sum(axis=1).astype(np.float64),
        n_tm=by_class[:, TM].astype(np.float64), n_cm=by_class[:, CM].astype(np.float64),
        n_gm=by_class[:, GM].astype(np.float64), n_om=by_class[:, OM].astype(np.float64),
        n_target=np.full(k, float(np.count_nonzero(arr.cls == TM))), n_seen=np.full(k, total_seen),
        n_seen_matched=seen_matched.astype(np.float64) if arr.seen_known else np.full(k, np.nan),
    )
    return values, counts


def sweep(arr: FrameArrays) -> pd.DataFrame:
    """One row per distinct score, ascending: sigma, every count and every threshold metric (NaN = undefined)."""
    values, counts = sweep_counts(arr)
    return pd.DataFrame({"sigma": values, **counts, **ratios(counts)}, copy=False)  # no 25-column consolidation


def sweep_loop(arr: FrameArrays, sigmas: Sequence[float] | np.ndarray | None = None) -> pd.DataFrame:
    """The same table, one full pass over the frames per threshold (default: every distinct score)."""
    sigmas = np.unique(arr.score) if sigmas is None else np.asarray(sigmas, np.float64)
    rows = [{"sigma": float(s), **threshold_metrics(arr, float(s))} for s in sigmas]
    return pd.DataFrame(rows, columns=["sigma", *COUNT_KEYS, *METRIC_KEYS])
