"""PIN's detection metrics and ours, as pure functions of a scored-frame table and sigma.

Every threshold metric is a ratio of integer counts (matched frames per class, matched
episodes, first matches...). Counting and dividing are kept apart: per-episode counts are
summed for the whole set, per category, per bootstrap resample, or (in ``sweep``) for every
sigma at once, and one ``ratios`` function turns any of them into metrics, so all paths
agree to the last bit. A ratio with a zero denominator is undefined: NaN here, None in the
dicts this module returns, never 0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from pin_match.errors import PinMatchError
from pin_match.evaluation.core.labels import CM, GM, OM, TM, frame_classes
from pin_match.scoring.table import require_finite

SCORED_COLUMNS = ["frame_id", "episode_id", "step", "target_category", "target_visible", "same_visible",
                  "other_visible", "target_seen", "score"]

COUNT_KEYS = ("n_episodes", "n_matched_episodes", "n_first_tm", "n_frames", "n_matched", "n_tm", "n_cm", "n_gm",
              "n_om", "n_target", "n_seen", "n_seen_matched")
METRIC_KEYS = ("match_pct", "tm_pct", "cm_pct", "nm_pct", "gm_pct", "om_pct", "target_recall",
               "target_recall_seen", "false_positive_rate", "f1", "first_match_precision", "first_match_success")
RANKING_KEYS = ("auroc_target", "ap_target", "auroc_same", "ap_same")
LOCALISATION_KEYS = ("localisation_accuracy", "localisation_point_precision")


class MetricsError(PinMatchError, ValueError):
    """A scored-frame table the metrics cannot be computed on."""


@dataclass(frozen=True)
class FrameArrays:
    """A scored-frame table as flat arrays, frames ordered by (episode, step)."""

    score: np.ndarray        # float64
    cls: np.ndarray          # int8 class code (TM, CM, GM, OM) from visibility alone
    episode: np.ndarray      # int64 episode code, non-decreasing
    seen: np.ndarray         # int8: 1 if the target is "seen" by PIN's strict rule
    seen_known: bool         # False when any frame's "seen" is undecidable (no depth)
    episode_ids: np.ndarray  # per episode code
    categories: np.ndarray   # target category per episode code

    @property
    def n_episodes(self) -> int:
        return len(self.episode_ids)


def frame_arrays(scored: pd.DataFrame) -> FrameArrays:
    """Validate a scored-frame table and order it by episode and step (a no-op when already so)."""
    missing = [c for c in SCORED_COLUMNS if c not in scored.columns]
    if missing:
        raise MetricsError(f"scored-frame table lacks columns {missing}")
    require_finite(scored.frame_id, scored.score, "scored-frame table", MetricsError)
    score = scored["score"].to_numpy(np.float64)
    codes, episode_ids = pd.factorize(scored["episode_id"], sort=False)
    step = scored["step"].to_numpy(np.int64)
    order = None
    if len(codes) > 1:
        d_ep, d_step = np.diff(codes), np.diff(step)
        if (d_ep < 0).any() or ((d_ep == 0) & (d_step <= 0)).any():
            order = np.lexsort((step, codes))
            codes, step = codes[order], step[order]
            d_ep, d_step = np.diff(codes), np.diff(step)
        dup = np.flatnonzero((d_ep == 0) & (d_step == 0))
        if dup.size:
            raise MetricsError(f"episode {episode_ids[codes[dup[0]]]!r} has two frames at step {step[dup[0]]}")

    def col_of(a: np.ndarray) -> np.ndarray:
        return a if order is None else a[order]

    def col(name: str) -> np.ndarray:
        return col_of(scored[name].to_numpy())

    starts = np.flatnonzero(np.r_[True, np.diff(codes) != 0]) if len(codes) else np.zeros(0, np.int64)
    first_rows = starts if order is None else order[starts]  # each episode's first frame, in table rows

    cls = col_of(frame_classes(scored))
    seen = col("target_seen").astype(np.float64)
    return FrameArrays(score=score if order is None else score[order], cls=cls,
                       episode=codes.astype(np.int64), seen=np.nan_to_num(seen, nan=0.0).astype(np.int8),
                       seen_known=not np.isnan(seen).any(), episode_ids=np.asarray(episode_ids),
                       categories=scored["target_category"].iloc[first_rows].to_numpy())


Scored = pd.DataFrame | FrameArrays  # a scored-frame table, or its arrays when the caller already has them


def as_arrays(scored: Scored) -> FrameArrays:
    """The arrays of a scored split: converted (validated, sorted) here, or passed through when already converted.

    Tuning and reporting compute several metrics of one split; converting it once and passing the
    arrays to each keeps the sort and the finiteness check to one per split.
    """
    return scored if isinstance(scored, FrameArrays) else frame_arrays(scored)


def episode_counts(arr: FrameArrays, sigma: float) -> dict[str, np.ndarray]:
    """Every count of ``COUNT_KEYS`` per episode (arrays of length n_episodes) at threshold sigma."""
    n = arr.n_episodes
    m = arr.score >= sigma

    def per_episode(mask: np.ndarray) -> np.ndarray:
        return np.bincount(arr.episode[mask], minlength=n).astype(np.float64)

    matched = np.flatnonzero(m)
    ep = arr.episode[matched]
    first = matched[np.r_[True, ep[1:] != ep[:-1]]] if matched.size else matched
    n_first_tm = np.zeros(n)
    n_first_tm[arr.episode[first]] = arr.cls[first] == TM
    counts = dict(n_episodes=np.ones(n), n_matched_episodes=(per_episode(m) > 0).astype(np.float64),
                  n_first_tm=n_first_tm, n_frames=per_episode(np.ones_like(m)), n_matched=per_episode(m),
                  n_tm=per_episode(m & (arr.cls == TM)), n_cm=per_episode(m & (arr.cls == CM)),
                  n_gm=per_episode(m & (arr.cls == GM)), n_om=per_episode(m & (arr.cls == OM)),
                  n_target=per_episode(arr.cls == TM), n_seen=per_episode(arr.seen == 1),
                  n_seen_matched=per_episode(m & (arr.seen == 1)))
    if not arr.seen_known:
        counts["n_seen"] = counts["n_seen_matched"] = np.full(n, np.nan)
    return counts


def ratios(c: Mapping[str, np.ndarray | float]) -> dict[str, np.ndarray]:
    """``METRIC_KEYS`` from summed counts (scalars or arrays of equal shape); NaN where undefined."""

    def pct(num: np.ndarray | float, den: np.ndarray | float) -> np.ndarray:
        num, den = np.broadcast_arrays(np.asarray(num, np.float64) * 100.0, np.asarray(den, np.float64))
        return np.divide(num, den, out=np.full(num.shape, np.nan), where=den > 0)

    matched, tm = c["n_matched"], c["n_tm"]
    nm = np.asarray(c["n_gm"]) + np.asarray(c["n_om"])
    return dict(
        match_pct=pct(c["n_matched_episodes"], c["n_episodes"]),
        tm_pct=pct(tm, matched), cm_pct=pct(c["n_cm"], matched), nm_pct=pct(nm, matched),
        gm_pct=pct(c["n_gm"], matched), om_pct=pct(c["n_om"], matched),
        target_recall=pct(tm, c["n_target"]),
        target_recall_seen=pct(c["n_seen_matched"], c["n_seen"]),  # NaN denominator: undecidable
        false_positive_rate=pct(np.asarray(matched) - tm, np.asarray(c["n_frames"]) - c["n_target"]),
        f1=pct(2 * np.asarray(tm), np.asarray(matched) + c["n_target"]),  # 2PR/(P+R) = 2TM/(matched+targets)
        first_match_precision=pct(c["n_first_tm"], c["n_matched_episodes"]),
        first_match_success=pct(c["n_first_tm"], c["n_episodes"]),
    )


def to_python(value: float) -> float | None:
    """A JSON-ready number: NaN (undefined) becomes None."""
    return None if math.isnan(value) else float(value)


def threshold_metrics(arr: FrameArrays, sigma: float) -> dict[str, float]:
    """Counts and metrics at one sigma as plain floats (NaN where undefined)."""
    c = {k: float(np.sum(v)) for k, v in episode_counts(arr, sigma).items()}
    if not arr.seen_known:  # also when there is no episode to carry the NaN
        c["n_seen"] = c["n_seen_matched"] = math.nan
    return {**c, **{k: float(v) for k, v in ratios(c).items()}}


def detection_metrics(arr: FrameArrays, sigma: float) -> dict[str, float | int | None]:
    """Every metric of one matcher at threshold sigma (score >= sigma is matched); None = undefined.

    It reads a split's arrays (``EvalContext.arrays``, or ``frame_arrays`` of a scored table), converted once by the
    caller for every metric, sweep and plot of that split."""
    out: dict[str, float | int | None] = {"sigma": float(sigma)}
    values = {**threshold_metrics(arr, sigma), **ranking_metrics(arr)}
    for k, v in values.items():
        out[k] = (None if math.isnan(v) else int(v)) if k in COUNT_KEYS else to_python(v)
    return out


def per_category(scored: Scored, sigma: float) -> pd.DataFrame:
    """The metrics per target category (rows, sorted), from the episodes whose target is of it."""
    arr = as_arrays(scored)
    counts = pd.DataFrame(episode_counts(arr, sigma))
    counts["category"] = arr.categories
    sums = counts.groupby("category", sort=True).sum(min_count=1)
    table = pd.concat([sums, pd.DataFrame(ratios({k: sums[k].to_numpy() for k in COUNT_KEYS}), index=sums.index)],
                      axis=1)
    frame_category = arr.categories[arr.episode]
    for name in RANKING_KEYS:
        table[name] = np.nan
    for category in table.index:
        sub = ranking_metrics(_subset(arr, frame_category == category))
        for name, value in sub.items():
            table.loc[category, name] = value
    for k in COUNT_KEYS:
        if not table[k].isna().any():
            table[k] = table[k].astype(np.int64)
    return table


def _subset(arr: FrameArrays, keep: np.ndarray) -> FrameArrays:
    return FrameArrays(score=arr.score[keep], cls=arr.cls[keep],
                       episode=arr.episode[keep], seen=arr.seen[keep], seen_known=arr.seen_known,
                       episode_ids=arr.episode_ids, categories=arr.categories)


# --------------------------------------------------------------------------- ranking (threshold-free)
def ranking_metrics(arr: FrameArrays) -> dict[str, float]:
    """AUROC and average precision of the raw score: target frames vs all others, and vs same-category frames."""
    target = arr.cls == TM
    same = arr.cls == CM
    return dict(auroc_target=auroc(arr.score[target], arr.score[~target]),
                ap_target=average_precision(arr.score, target),
                auroc_same=auroc(arr.score[target], arr.score[same]),
                ap_same=average_precision(arr.score[target | same], target[target | same]))


def auroc(positives: np.ndarray, negatives: np.ndarray) -> float:
    """P(score of a random positive > a random negative), ties counting one half (Mann-Whitney U)."""
    n_pos, n_neg = len(positives), len(negatives)
    if n_pos == 0 or n_neg == 0:
        return math.nan
    values, inverse, counts = np.unique(np.concatenate([positives, negatives]), return_inverse=True,
                                        return_counts=True)
    mid_rank = np.cumsum(counts) - (counts - 1) / 2.0  # 1-based average rank of each distinct value
    rank_sum = mid_rank[inverse[:n_pos]].sum()
    return float((rank_sum - n_pos * (n_pos + 1) / 2.0) / (n_pos * n_neg))


def average_precision(scores: np.ndarray, positive: np.ndarray) -> float:
    """Area under the step precision-recall curve, one step per distinct score (tied scores enter together)."""
    n_pos = int(np.count_nonzero(positive))
    if n_pos == 0:
        return math.nan
    values, inverse = np.unique(-np.asarray(scores, np.float64), return_inverse=True)  # descending scores
    tp = np.cumsum(np.bincount(inverse, weights=positive, minlength=len(values)))
    seen = np.cumsum(np.bincount(inverse, minlength=len(values)))
    recall_gain = np.diff(np.r_[0.0, tp]) / n_pos
    return float(np.sum(recall_gain * tp / seen))


# --------------------------------------------------------------------------- localisation and uncertainty
def localisation_metrics(hits: pd.DataFrame) -> dict[str, float | None]:
    """From ``labels.localisation_hits``: % of matched target frames with a point on the target, % of points on it."""
    n_frames, n_points = len(hits), int(hits["n_points"].sum()) if len(hits) else 0
    return dict(localisation_accuracy=100.0 * float(hits["hit"].sum()) / n_frames if n_frames else None,
                localisation_point_precision=100.0 * float(hits["n_on_target"].sum()) / n_points if n_points else None,
                n_localised_frames=n_frames)


@dataclass(frozen=True)
class Bootstrap:
    """How an interval is resampled: how many resamples, the generator's seed, the coverage."""

    n_boot: int = 1000
    seed: int = 0
    level: float = 0.95


DEFAULT_BOOT = Bootstrap()  # the default of every ``boot=`` parameter (frozen, so one shared instance is safe)
