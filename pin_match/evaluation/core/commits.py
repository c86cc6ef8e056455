"""What a stop policy did, episode by episode: where it fired and committed, the class of the frame it chose, how
long it looked, and PIN's metrics read through it (``policy_metrics``).

Where a frame-set has no geometry (real photos) there is no walk to follow, but the policy still
decides which frame the agent would commit to (``StopPolicy.decide``, every candidate placeable).
The share of episodes committed to the target, to a look-alike or to something else, the share
still looking when the walk ended (a window that ran past its last frame), and the frames looked
at before committing, are then what a look-further policy buys and costs; with geometry they
stand beside the navigation estimate, which reads the same decisions.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from pin_match.evaluation.core.intervals import Clusters, per_episode_intervals
from pin_match.evaluation.core.labels import CLASSES, CM, TM
from pin_match.evaluation.core.metrics import (
    DEFAULT_BOOT,
    Bootstrap,
    FrameArrays,
    Scored,
    as_arrays,
    threshold_metrics,
    to_python,
)
from pin_match.evaluation.core.stop import (
    FIRST_MATCH,
    Decision,
    StopPolicy,
    episode_bounds,
    fired_arrays,
    found_frames,
)

COMMIT_COLUMNS = ["episode_id", "committed_step", "committed_class", "committed_score", "fired_step", "commit_step",
                  "looked_frames", "candidates", "rejected"]
COMMIT_SHARES = ("commit_target_pct", "commit_lookalike_pct", "commit_other_pct", "commit_none_pct",
                 "still_looking_pct")  # each the % of episodes with a yes/no outcome (their intervals: intervals.py)
COMMIT_KEYS = (*COMMIT_SHARES, "frames_looked_at")


def commitments(arr: FrameArrays, sigma: float, policy: StopPolicy,
                decisions: list[Decision] | None = None) -> pd.DataFrame:
    """One row per episode (``COMMIT_COLUMNS``): the frame committed to (0-based step, class TM / CM / GM / OM,
    score), the firing that opened the window, the frame where the agent committed, the frames it had looked at by
    then (1-based), how many candidates it weighed and how many of them it walked up to and rejected; None where it
    never commits. An episode still looking when the walk ended (a window still open, or every candidate rejected)
    has its firing and candidates but no commit; it looked at its whole walk. ``decisions``: the policy's, where the
    caller made them with what the house says (``navigation.walk_decisions``); None: ``policy.decide`` with every
    candidate placeable and its own frame for its close look."""
    rows = []
    for (start, end), d in zip(episode_bounds(arr), decisions or policy.decide(arr, sigma)):
        episode_id = str(arr.episode_ids[arr.episode[start]])
        if d.chosen is None:
            rows.append(dict(episode_id=episode_id, fired_step=None if d.fired is None else d.fired - start,
                             looked_frames=end - start, candidates=len(d.candidates), rejected=len(d.rejected)))
            continue
        fired, stop = int(d.fired), int(d.stop)  # type: ignore[arg-type]  # a committed decision has both
        rows.append(dict(episode_id=episode_id, committed_step=d.chosen - start,
                         committed_class=CLASSES[arr.cls[d.chosen]], committed_score=float(arr.score[d.chosen]),
                         fired_step=fired - start, commit_step=stop - start, looked_frames=stop - start + 1,
                         candidates=len(d.candidates), rejected=len(d.rejected)))
    steps = ["committed_step", "fired_step", "commit_step", "looked_frames", "candidates", "rejected"]
    return pd.DataFrame(rows, columns=COMMIT_COLUMNS).astype({column: "Int64" for column in steps})


def commit_shares(rows: pd.DataFrame, weights: np.ndarray | None = None) -> dict[str, float]:
    """% of episodes committed to the target, to a look-alike, to anything else, to nothing (it never fired on a
    placeable candidate), still looking (its window was open when the walk ended; the five add up to 100); the mean
    frames looked at (every episode: one that never commits looked at its whole walk), each episode counted
    ``weights`` times."""
    w = np.ones(len(rows)) if weights is None else np.asarray(weights, np.float64)
    total = w.sum()
    if not total:
        return {key: math.nan for key in COMMIT_KEYS}
    cls, opened = rows["committed_class"], rows["fired_step"].notna()

    def share(mask: pd.Series) -> float:
        return float(100 * np.dot(w, mask.to_numpy(np.float64)) / total)

    return dict(commit_target_pct=share(cls == CLASSES[TM]), commit_lookalike_pct=share(cls == CLASSES[CM]),
                commit_other_pct=share(cls.notna() & ~cls.isin([CLASSES[TM], CLASSES[CM]])),
                commit_none_pct=share(cls.isna() & ~opened), still_looking_pct=share(cls.isna() & opened),
                frames_looked_at=float(np.dot(w, rows["looked_frames"].to_numpy(np.float64)) / total))


def commit_metrics(rows: pd.DataFrame, clusters: Clusters | None = None, boot: Bootstrap = DEFAULT_BOOT) -> dict:
    """``commit_shares`` with percentile intervals resampling target instances (``clusters``), as every metric."""
    point, ci = per_episode_intervals(rows, commit_shares, clusters, boot, shares=COMMIT_SHARES)
    return dict(metrics={k: to_python(v) for k, v in point.items()}, ci95=ci, n_episodes=len(rows))


def policy_metrics(scored: Scored, sigma: float, policy: StopPolicy = FIRST_MATCH,
                   decisions: list[Decision] | None = None) -> dict[str, float]:
    """PIN's counts and metrics with "matched" read as "found under the policy", plus how long it looked.

    ``frames_to_first_match``: the mean, over episodes where something is found, of the 1-based position of the
    first found frame (for a look-further policy, the frame it commits to), NaN where nothing is found;
    ``frames_looked_at``: ``commit_shares``' (the 1-based frame where the agent committed, the whole walk where it
    never does). ``look:0`` gives PIN's rule exactly (``LookFurther.found``). ``decisions``: the policy's, where the
    caller made them with what the house says (``navigation.walk_decisions``), so these metrics and the navigation
    estimate read one outcome.
    """
    arr = as_arrays(scored)
    found = found_frames(arr, sigma, policy, decisions)
    out = threshold_metrics(fired_arrays(arr, found), 0.5)
    first = np.flatnonzero(found)
    if first.size:
        first = first[np.r_[True, arr.episode[first][1:] != arr.episode[first][:-1]]]
        out["frames_to_first_match"] = float(np.mean(first - np.searchsorted(arr.episode, arr.episode[first]) + 1))
    else:
        out["frames_to_first_match"] = math.nan
    out["frames_looked_at"] = commit_shares(commitments(arr, sigma, policy, decisions))["frames_looked_at"]
    return out


STOP_COLUMNS = ["episode_id", "first_step", "first_class", "first_score", "stop_step", "stop_class", "stop_score",
                "stop_level", "stop_line", "commit_step", "chosen_step", "chosen_class", "chosen_score", "candidates",
                "peak_step", "peak_score", "peak_level", "peak_offset"]


def episode_stops(arr: FrameArrays, sigma: float, policy: StopPolicy,
                  decisions: list[Decision] | None = None) -> pd.DataFrame:
    """Per episode (``STOP_COLUMNS``): PIN's first match at sigma (step: the frame's 0-based position in its episode,
    class, score); where the policy fired (the window opened, ``Decision.fired``), the house's level there
    (``policy.level``, NaN without one) and the line the frame reached; where it stopped looking (``commit_step``),
    the frame it committed to and every candidate it weighed (``step:score``, ``;``-separated); and the target's best
    frame: its score, the level before it and how far above it the target came (its offset). None where there is no
    such frame. ``decisions``: as for ``policy_metrics``."""
    level, line = policy.level(arr), policy.line(arr, sigma)
    first = arr.score >= sigma
    target = arr.cls == TM
    rows = []
    for (start, end), decision in zip(episode_bounds(arr), decisions or policy.decide(arr, sigma)):
        row = dict(episode_id=str(arr.episode_ids[arr.episode[start]]))
        hit = np.flatnonzero(first[start:end])
        row |= _frame_fields(arr, "first", start + int(hit[0]) if hit.size else None, start)
        t = decision.fired
        row |= _frame_fields(arr, "stop", t, start)
        row |= dict(stop_level=None if t is None else _number(level[t]),
                    stop_line=None if t is None else float(line[t]),
                    commit_step=None if decision.stop is None else decision.stop - start)
        row |= _frame_fields(arr, "chosen", decision.chosen, start)
        row["candidates"] = "; ".join(f"{c - start}:{arr.score[c]:.3f}" for c in decision.candidates) or None
        seen = np.flatnonzero(target[start:end])
        t = start + int(seen[np.argmax(arr.score[start:end][seen])]) if seen.size else None
        row |= dict(peak_step=None if t is None else t - start, peak_score=None if t is None else float(arr.score[t]),
                    peak_level=None if t is None else _number(level[t]),
                    peak_offset=None if t is None else _number(arr.score[t] - level[t]))
        rows.append(row)
    return pd.DataFrame(rows, columns=STOP_COLUMNS)


def _frame_fields(arr: FrameArrays, name: str, t: int | None, start: int) -> dict:
    if t is None:
        return {f"{name}_step": None, f"{name}_class": None, f"{name}_score": None}
    return {f"{name}_step": t - start, f"{name}_class": CLASSES[arr.cls[t]], f"{name}_score": float(arr.score[t])}


def _number(value: float) -> float | None:
    return None if np.isnan(value) else float(value)
