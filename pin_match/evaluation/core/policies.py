"""PIN's detection metrics under a stop policy, and sigma chosen for one.

PIN's rule stops at the first frame at or above sigma (1-of-1). Agents that confirm over
several frames stop when ``k`` of the last ``n`` frames of the episode are at or above sigma
(k-of-n); a house-relative policy also asks the frame to clear the house's own level
(``stop.HouseStop``). A frame where the policy fires is "found"; the metrics are PIN's, computed on
found frames instead of matched ones, by the same counting code (``metrics``), so 1-of-1
equals today's metrics exactly. Definitions: docs/metrics.md, "Stop policies".
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.commits import policy_metrics
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.metrics import COUNT_KEYS, METRIC_KEYS, Scored, as_arrays, threshold_metrics, to_python
from pin_match.evaluation.core.navigation import sweep_sigmas, walk_decisions
from pin_match.evaluation.core.stop import (
    FIRST_MATCH,
    ApproachVerify,
    Decision,
    PolicyError,
    StopPolicy,
    fired_arrays,
    found_frames,
    gated_scores,
)
from pin_match.evaluation.core.sweep import sweep
from pin_match.evaluation.core.tuning import (
    DEFAULT_MATCH_FLOOR,
    DEFAULT_OBJECTIVE,
    OBJECTIVES,
    choose_sigma,
    objective_curve,
)
from pin_match.scoring.table import ScoreTable

MAX_CANDIDATES = 2000  # sigmas tried where one sweep cannot serve: every distinct score, or this many quantiles
SECOND_LINE_LEVELS = np.linspace(0.5, 0.95, 4)  # quantiles of the walk's scores (a recording's approach views') tried
# as an approach's second line


def policy_sweep(scored: Scored, policy: StopPolicy,
                 decisions_at: Callable[[float], list[Decision]] | None = None) -> pd.DataFrame:
    """Every count and threshold metric of ``policy_metrics`` at every distinct score as sigma (ascending): the table
    ``tuning.choose_sigma`` reads. A 1-of-1 window is one sorted sweep of the gated scores (``stop.gated_scores``),
    read at every distinct score; a longer window or a look-further policy applies each sigma in turn, at most
    ``MAX_CANDIDATES`` of them. An approach-verify policy walks up to its candidates in the house: it needs
    ``decisions_at(sigma)`` (``navigation.walk_decisions``) and reads the sigmas ``navigation.sweep_sigmas`` gives it,
    each walk-up rendered and scored once."""
    arr = as_arrays(scored)
    if isinstance(policy, ApproachVerify):
        if decisions_at is None:
            raise PolicyError(f"stop policy {policy} walks up to each candidate: its metrics need the house's walk-ups "
                              "(a frame-set with geometry and the matcher: pin-match tune / report / trade)")
        rows = [{"sigma": s, **threshold_metrics(fired_arrays(arr, found_frames(arr, s, policy, decisions_at(s))),
                                                 0.5)} for s in sweep_sigmas(arr.score, policy)]
        return pd.DataFrame(rows, columns=["sigma", *COUNT_KEYS, *METRIC_KEYS])
    scores = np.unique(arr.score)
    if policy.one_sweep:
        gated = replace(arr, score=gated_scores(arr, policy))
        curve = sweep(gated)
        never = pd.DataFrame([{"sigma": np.inf, **threshold_metrics(gated, np.inf)}])  # above every gated score
        rows = pd.concat([curve, never], ignore_index=True).iloc[np.searchsorted(curve["sigma"], scores)]
        return rows.assign(sigma=scores).reset_index(drop=True)[["sigma", *COUNT_KEYS, *METRIC_KEYS]]
    if len(scores) > MAX_CANDIDATES:
        scores = np.unique(np.quantile(scores, np.linspace(0.0, 1.0, MAX_CANDIDATES)))
    rows = [{"sigma": s, **threshold_metrics(fired_arrays(arr, found_frames(arr, s, policy)), 0.5)} for s in scores]
    return pd.DataFrame(rows, columns=["sigma", *COUNT_KEYS, *METRIC_KEYS])


def policy_sigma(scored: Scored, policy: StopPolicy = FIRST_MATCH, objective: str = DEFAULT_OBJECTIVE,
                 match_floor: float = DEFAULT_MATCH_FLOOR) -> float:
    """The sigma ``objective`` chooses for ``policy`` on scored frames (for 1-of-1, ``tuning.sigma_for``'s)."""
    curve = policy_sweep(scored, policy)
    return float(curve["sigma"].iloc[choose_sigma(curve, objective, match_floor)[0]])


def tune_policy(table: ScoreTable, fs: FrameSet, policy: StopPolicy, objective: str = DEFAULT_OBJECTIVE,
                split: str = "train", match_floor: float = DEFAULT_MATCH_FLOOR) -> dict:
    """``tuning.tune`` for a stop policy: the sigma that maximises the objective of the policy's metrics (for a
    navigation objective, of the navigation estimate under the policy). An approach-verify policy without a second
    line of its own (``approach:D``) has both tuned: sigma for each second line tried (sigma itself, then
    ``SECOND_LINE_LEVELS`` of the split's scores), the best pair kept (the earlier among equals) and its
    ``policy`` written with the line it chose."""
    ctx = EvalContext.of(fs)
    arr = ctx.arrays(table, split)
    navigation = objective in OBJECTIVES and OBJECTIVES[objective].navigation
    places = ctx.placements(table, split) if ctx.fs.navigation_missing is None else None

    def decisions_at(candidate: StopPolicy) -> Callable[[float], list[Decision]] | None:
        return None if places is None else lambda s: walk_decisions(places, s, candidate)[0]

    best = None
    for candidate in _with_each_second_line(ctx, table, split, policy):
        curve = objective_curve(ctx, table, split, objective, candidate) if navigation else \
            policy_sweep(arr, candidate, decisions_at(candidate))
        index, value = choose_sigma(curve, objective, match_floor)
        if best is None or value > best[2]:
            best = (candidate, float(curve["sigma"].iloc[index]), value, len(curve))
    policy, sigma, value, n_candidates = best  # type: ignore[misc]  # one candidate at least
    return dict(matcher=table.matcher, matcher_id=table.matcher_id, config_hash=table.meta.get("config_hash"),
                sigma=sigma, policy=str(policy), objective=objective, objective_value=value, split=split,
                frameset_fingerprint=table.meta.get("frameset_fingerprint"), n_frames=len(arr.score),
                n_candidates=n_candidates,
                metrics_at_sigma={k: to_python(v) for k, v in policy_metrics(
                    arr, sigma, policy, None if places is None else walk_decisions(places, sigma, policy)[0]).items()},
                date=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))


def _with_each_second_line(ctx: EvalContext, table: ScoreTable, split: str, policy: StopPolicy) -> list[StopPolicy]:
    """The policies ``tune_policy`` tries: ``policy`` itself, and for an approach without a second line each of
    ``SECOND_LINE_LEVELS`` (quantiles of the split's recorded approach views' scores, of its walk's where it has none:
    a synthetic set's walk-ups are rendered only as a policy walks up)."""
    if not isinstance(policy, ApproachVerify) or policy.sigma2 is not None:
        return [policy]
    views = ctx.approach_scored(table, split)["score"].to_numpy(np.float64)
    scores = views if len(views) else ctx.arrays(table, split).score
    lines = np.unique(np.quantile(scores, SECOND_LINE_LEVELS))
    return [policy, *(replace(policy, sigma2=float(line)) for line in lines)]
