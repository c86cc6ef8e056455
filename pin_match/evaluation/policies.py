"""Stop policies: when an agent that watches a sequence of frames declares the target found.

PIN's rule stops at the first frame at or above sigma (1-of-1). Agents that confirm over
several frames stop when ``k`` of the last ``n`` frames of the episode are at or above sigma
(k-of-n). A frame where the policy fires is "found"; the metrics are PIN's, computed on
found frames instead of matched ones, by the same counting code (``metrics``), so 1-of-1
equals today's metrics exactly. Definitions: docs/metrics.md, "Stop policies".
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import replace

import numpy as np
import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.evaluation.evaluator import EvalContext
from pin_match.evaluation.metrics import METRIC_KEYS, frame_arrays, threshold_metrics, to_python
from pin_match.evaluation.stop import FIRST_MATCH, StopPolicy, found_frames
from pin_match.evaluation.tuning import (
    DEFAULT_MATCH_FLOOR,
    DEFAULT_OBJECTIVE,
    OBJECTIVES,
    choose_sigma,
    objective_curve,
)
from pin_match.scoring.table import ScoreTable

MAX_CANDIDATES = 2000  # sigmas tried when tuning for a policy: every distinct score, or this many quantiles


def policy_metrics(scored: pd.DataFrame, sigma: float, policy: StopPolicy = FIRST_MATCH) -> dict[str, float]:
    """PIN's counts and metrics with "matched" read as "the policy fires", plus frames to the first firing.

    ``frames_to_first_match``: the mean, over episodes where the policy fires, of the 1-based
    position of the first frame where it does (NaN when it never fires).
    """
    arr = frame_arrays(scored)
    found = found_frames(arr, sigma, policy)
    out = threshold_metrics(replace(arr, score=found.astype(np.float64)), 0.5)
    first = np.flatnonzero(found)
    if first.size:
        first = first[np.r_[True, arr.episode[first][1:] != arr.episode[first][:-1]]]
        starts = np.searchsorted(arr.episode, arr.episode[first])
        out["frames_to_first_match"] = float(np.mean(first - starts + 1))
    else:
        out["frames_to_first_match"] = math.nan
    return out


def policy_sweep(scored: pd.DataFrame, policy: StopPolicy) -> pd.DataFrame:
    """``policy_metrics`` at every candidate sigma (ascending): the table ``tuning.choose_sigma`` reads."""
    scores = np.unique(scored["score"].to_numpy(np.float64))
    if len(scores) > MAX_CANDIDATES:
        scores = np.unique(np.quantile(scores, np.linspace(0.0, 1.0, MAX_CANDIDATES)))
    rows = [{"sigma": s, **policy_metrics(scored, s, policy)} for s in scores]
    return pd.DataFrame(rows, columns=["sigma", *METRIC_KEYS, "frames_to_first_match"])


def tune_policy(table: ScoreTable, fs: FrameSet, policy: StopPolicy, objective: str = DEFAULT_OBJECTIVE,
                split: str = "train", match_floor: float = DEFAULT_MATCH_FLOOR) -> dict:
    """``tuning.tune`` for a stop policy: the sigma that maximises the objective of the policy's metrics (for a
    navigation objective, of the navigation estimate under the policy)."""
    ctx = EvalContext.of(fs)
    scored = ctx.scored(table, split)
    navigation = objective in OBJECTIVES and OBJECTIVES[objective].navigation
    curve = objective_curve(ctx, table, split, objective, policy) if navigation else policy_sweep(scored, policy)
    index, value = choose_sigma(curve, objective, match_floor)
    sigma = float(curve["sigma"].iloc[index])
    return dict(matcher=table.matcher, matcher_id=table.matcher_id, config_hash=table.meta.get("config_hash"),
                sigma=sigma, policy=str(policy), objective=objective, objective_value=value, split=split,
                frameset_fingerprint=table.meta.get("frameset_fingerprint"), n_frames=len(scored),
                n_candidates=len(curve),
                metrics_at_sigma={k: to_python(v) for k, v in policy_metrics(scored, sigma, policy).items()},
                date=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))
