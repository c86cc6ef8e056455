"""What a stop policy committed to, episode by episode: the class of the frame it chose and how long it looked.

Where a frame-set has no geometry (real photos) there is no walk to follow, but the policy still
decides which frame the agent would commit to (``StopPolicy.decide``, every candidate placeable).
The share of episodes committed to the target, to a look-alike or to something else, and the
frames looked at before committing, are then what a look-further policy buys and costs; with
geometry they stand beside the navigation estimate, which reads the same decisions.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from pin_match.evaluation.core.intervals import Clusters, per_episode_intervals
from pin_match.evaluation.core.labels import CLASSES, CM, TM
from pin_match.evaluation.core.metrics import DEFAULT_BOOT, Bootstrap, FrameArrays, to_python
from pin_match.evaluation.core.stop import StopPolicy, episode_bounds

COMMIT_COLUMNS = ["episode_id", "committed_step", "committed_class", "committed_score", "fired_step", "commit_step",
                  "looked_frames", "candidates"]
COMMIT_KEYS = ("commit_target_pct", "commit_lookalike_pct", "commit_other_pct", "commit_none_pct", "frames_looked_at")


def commitments(arr: FrameArrays, sigma: float, policy: StopPolicy) -> pd.DataFrame:
    """One row per episode (``COMMIT_COLUMNS``): the frame committed to (0-based step, class TM / CM / GM / OM,
    score), the firing that opened the window, the frame where the agent committed, the frames it had looked at by
    then (1-based) and how many candidates it weighed; None where it never commits."""
    rows = []
    for (start, end), d in zip(episode_bounds(arr), policy.decide(arr, sigma)):
        episode_id = str(arr.episode_ids[arr.episode[start]])
        if d.chosen is None:
            rows.append(dict(episode_id=episode_id, looked_frames=end - start, candidates=0))
            continue
        fired, stop = int(d.fired), int(d.stop)  # type: ignore[arg-type]  # a committed decision has both
        rows.append(dict(episode_id=episode_id, committed_step=d.chosen - start,
                         committed_class=CLASSES[arr.cls[d.chosen]], committed_score=float(arr.score[d.chosen]),
                         fired_step=fired - start, commit_step=stop - start, looked_frames=stop - start + 1,
                         candidates=len(d.candidates)))
    return pd.DataFrame(rows, columns=COMMIT_COLUMNS)


def commit_shares(rows: pd.DataFrame, weights: np.ndarray | None = None) -> dict[str, float]:
    """% of episodes committed to the target, to a look-alike, to anything else, to nothing; the mean frames looked
    at (every episode: one that never commits looked at its whole walk), each episode counted ``weights`` times."""
    w = np.ones(len(rows)) if weights is None else np.asarray(weights, np.float64)
    total = w.sum()
    if not total:
        return {key: math.nan for key in COMMIT_KEYS}
    cls = rows["committed_class"]

    def share(mask: pd.Series) -> float:
        return float(100 * np.dot(w, mask.to_numpy(np.float64)) / total)

    return dict(commit_target_pct=share(cls == CLASSES[TM]), commit_lookalike_pct=share(cls == CLASSES[CM]),
                commit_other_pct=share(cls.notna() & ~cls.isin([CLASSES[TM], CLASSES[CM]])),
                commit_none_pct=share(cls.isna()),
                frames_looked_at=float(np.dot(w, rows["looked_frames"].to_numpy(np.float64)) / total))


def commit_metrics(rows: pd.DataFrame, clusters: Clusters | None = None, boot: Bootstrap = DEFAULT_BOOT) -> dict:
    """``commit_shares`` with percentile intervals resampling target instances (``clusters``), as every metric."""
    point, ci = per_episode_intervals(rows, commit_shares, clusters, boot)
    return dict(metrics={k: to_python(v) for k, v in point.items()}, ci95=ci, n_episodes=len(rows))
