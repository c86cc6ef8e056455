"""Choose a matcher's sigma on the train split by an objective, and keep where it came from.

The whole threshold curve comes from one ``sweep``; an objective scores every candidate
sigma (every distinct train score) and the best wins, ties going to the highest sigma, the
most conservative choice. ``pin_match.evaluation.core.sigma`` reads them back. Thresholds files
record the frame-set fingerprint, split, objective and the train metrics at sigma, so a reported
number can be traced back.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.metrics import Scored, as_arrays, detection_metrics
from pin_match.evaluation.core.navigation import episodes_at, metrics_of, navigation_sweep, sweep_sigmas
from pin_match.evaluation.core.stop import FIRST_MATCH, StopPolicy
from pin_match.evaluation.core.sweep import sweep
from pin_match.scoring.table import ScoreTable

DEFAULT_OBJECTIVE = "first-match"
DEFAULT_MATCH_FLOOR = 50.0
THRESHOLDS_DIR = Path("thresholds")


class TuningError(PinMatchError, ValueError):
    """No sigma can be chosen, or a thresholds file cannot be used."""


@dataclass(frozen=True)
class Objective:
    """A score per candidate sigma (a row of the sweep table); higher is better, NaN never wins."""

    description: str
    score: Callable[[pd.DataFrame, float], np.ndarray]  # (sweep table, %Match floor) -> values
    navigation: bool = False  # reads the navigation curve (``navigation.navigation_sweep``), not the detection one


OBJECTIVES: dict[str, Objective] = {
    "first-match": Objective(
        "% of all episodes whose first matched frame shows the target: what a modular agent that acts on its "
        "first detection achieves; it rewards precision and recall at once",
        lambda s, floor: s["first_match_success"].to_numpy()),
    "f1": Objective(
        "harmonic mean of TM precision (TM % of matched frames) and target recall (% of target frames matched)",
        lambda s, floor: s["f1"].to_numpy()),
    "youden": Objective(
        "Youden's J on frames: target recall minus the false-positive rate on frames without the target",
        lambda s, floor: (s["target_recall"] - s["false_positive_rate"]).to_numpy()),
    "tm-at-match": Objective(
        "highest TM % among the sigmas that keep %Match at or above a floor (default 50 %)",
        lambda s, floor: np.where(s["match_pct"].to_numpy() >= floor, s["tm_pct"].to_numpy(), np.nan)),
    "sr": Objective(
        "PIN's success rate as estimated from the recorded walks (docs/metrics.md, 'Navigation'), ties to the "
        "higher SPL's sigma; needs a frame-set with geometry; candidates: every distinct score, or 200 quantiles",
        lambda s, floor: (s["sr"] + 1e-6 * s["spl"]).to_numpy(), navigation=True),
}


def choose_sigma(table: pd.DataFrame, objective: str, match_floor: float = DEFAULT_MATCH_FLOOR) -> tuple[int, float]:
    """Row index of the best sigma in a sweep table (ascending sigma) and its objective value."""
    if objective not in OBJECTIVES:
        raise TuningError(f"unknown objective {objective!r}; choose one of {sorted(OBJECTIVES)}")
    values = np.asarray(OBJECTIVES[objective].score(table, match_floor), np.float64)
    if not len(values) or np.isnan(values).all():
        raise TuningError(f"objective {objective!r} is undefined at every candidate sigma"
                          + (f" (no sigma keeps %Match >= {match_floor})" if objective == "tm-at-match" else ""))
    best = np.nanmax(values)
    index = int(np.flatnonzero(values == best)[-1])  # ties: the highest sigma
    return index, float(best)


def sigma_for(scored: Scored, objective: str = DEFAULT_OBJECTIVE, match_floor: float = DEFAULT_MATCH_FLOOR) -> float:
    """The sigma ``objective`` chooses on scored frames (a table or its arrays), as ``tune`` chooses it."""
    curve = sweep(as_arrays(scored))
    return float(curve["sigma"].iloc[choose_sigma(curve, objective, match_floor)[0]])


def tune(table: ScoreTable, data: FrameSet | EvalContext, objective: str = DEFAULT_OBJECTIVE, split: str = "train",
         match_floor: float = DEFAULT_MATCH_FLOOR) -> dict:
    """Pick sigma for ``table``'s matcher on one split of ``data``; the result is what ``write_thresholds`` stores.

    The table must have been scored on the frame-set (``data``, or the run's ``EvalContext``); a
    split it lacks is an error that says how to go on (another split, an explicit sigma or the paper's).
    """
    ctx = EvalContext.of(data)
    arr = ctx.arrays(table, split)
    curve = objective_curve(ctx, table, split, objective)
    index, value = choose_sigma(curve, objective, match_floor)
    sigma = float(curve["sigma"].iloc[index])
    metrics = detection_metrics(arr, sigma)
    if ctx.fs.navigation_missing is None:
        metrics.update(metrics_of(episodes_at(ctx.placements(table, split), sigma)))
    result = dict(matcher=table.matcher, matcher_id=table.matcher_id, config_hash=table.meta.get("config_hash"),
                  sigma=sigma, objective=objective, objective_value=value, split=split,
                  frameset_fingerprint=table.meta.get("frameset_fingerprint"),
                  n_frames=len(arr.score), n_candidates=len(curve), metrics_at_sigma=metrics,
                  date=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))
    if objective == "tm-at-match":
        result["match_floor"] = match_floor
    return result


def objective_curve(ctx: EvalContext, table: ScoreTable, split: str, objective: str,
                    policy: StopPolicy = FIRST_MATCH) -> pd.DataFrame:
    """The candidate sigmas and what ``objective`` reads at each: the detection sweep, or for a navigation objective
    the navigation curve (a frame-set without geometry says why it has none)."""
    if objective in OBJECTIVES and OBJECTIVES[objective].navigation:
        reason = ctx.fs.navigation_missing
        if reason is not None:
            raise TuningError(f"objective {objective!r} needs the navigation estimate: {reason}")
        places = ctx.placements(table, split)
        return navigation_sweep(places, sweep_sigmas(places.arrays.score, policy), policy)
    return sweep(ctx.arrays(table, split))


def default_threshold_path(matcher: str, root: str | Path = THRESHOLDS_DIR) -> Path:
    return Path(root) / f"{matcher}.json"


def write_thresholds(result: dict, path: str | Path) -> Path:
    atomic.write_json(path, result)
    return Path(path)
