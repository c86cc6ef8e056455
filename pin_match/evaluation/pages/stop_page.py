"""The report's account of the stop: per episode, where the stop policy put the line and why, beside PIN's first match.

A reader who sees a house-relative policy stop late (or never) needs the house's level at that
frame, the line it made and how far above the house the target itself came; a reader of PIN's
rule needs the same table with the line at sigma; a reader of a look-further policy needs the
candidates it weighed in its window, their scores and the one it committed to. ``stop_html``
returns the pieces a page adds (``report_page`` places them); the numbers come from
``stop.episode_stops``, nothing is computed here.
"""

from __future__ import annotations

import math

import pandas as pd
from markupsafe import Markup

from pin_match.evaluation.core.commits import episode_stops
from pin_match.evaluation.core.metrics import FrameArrays
from pin_match.evaluation.core.stop import DEFAULT_POLICY, Decision, HouseStop, LookFurther, StopPolicy
from pin_match.evaluation.pages import html


def stop_html(arrays: FrameArrays, sigma: float, policy: StopPolicy = DEFAULT_POLICY,
              decisions: list[Decision] | None = None) -> list[Markup]:
    """A heading, what the policy does, and one row per episode: PIN's first match at sigma, the policy's stop with
    the house's level and line there and why it fired (or never did), and the target's best frame with its offset
    above the house."""
    stops = episode_stops(arrays, sigma, policy, decisions)
    return [html.heading("Where the stop rule put the line", 2, "stop"),
            html.paragraph(_rule(policy, sigma), "note"),
            html.table(stop_table(stops, sigma, policy))]


def stop_table(stops: pd.DataFrame, sigma: float, policy: StopPolicy) -> pd.DataFrame:
    """``stop.episode_stops`` as the page shows it, one row per episode (index: episode id)."""
    rows = {}
    for _, s in stops.iterrows():
        rows[s.episode_id] = {
            "first match (PIN's rule)": _frame(s.first_step, s.first_class, s.first_score),
            f"stop ({policy})": _frame(s.stop_step, s.stop_class, s.stop_score),
            "house level there": s.stop_level, "line there": s.stop_line, "why": _why(s, sigma, policy),
            "target's best": _frame(s.peak_step, "TM" if _known(s.peak_step) else None, s.peak_score),
            "house level before it": s.peak_level, "target's offset": s.peak_offset}
        if isinstance(policy, LookFurther):
            rows[s.episode_id] |= {
                "candidates (step:score)": s.candidates or "none",
                "committed at step": int(s.commit_step) if _known(s.commit_step) else
                "still looking at the walk's end" if _known(s.stop_step) else "never",
                "committed to": _frame(s.chosen_step, s.chosen_class, s.chosen_score)}
    table = pd.DataFrame.from_dict(rows, orient="index")
    table.index.name = "episode"
    return table


def _rule(policy: StopPolicy, sigma: float) -> str:
    if isinstance(policy, LookFurther):
        return (f"Policy {policy.describe()}. Sigma {sigma:g}. 'stop' is the firing that opened the window; the "
                "candidates are the firing frames it weighed until it committed, and the agent walks back to the one "
                "it committed to (its steps and path are counted).")
    window = "" if (policy.k, policy.n) == (1, 1) else f"; it stops when {policy.k} of the last {policy.n} frames do"
    if isinstance(policy, HouseStop):
        return (f"Policy {policy}: a frame counts when its score reaches sigma ({sigma:g}) and the house's level plus "
                f"{policy.margin:g}; the house's level is the mean of the {policy.top} highest scores of the episode's "
                f"earlier frames (the first frame has none: sigma alone){window}. The target's offset is how far its "
                "best frame came above the level before it: where it is below the margin, the house's own objects "
                "(or the target's earlier frames) set the line above the target.")
    return f"Policy {policy}: a frame counts when its score reaches sigma ({sigma:g}){window}; no house level is read."


def _frame(step: float | None, cls: str | None, score: float | None) -> str:
    return "none" if not _known(step) else f"step {int(step)}, {cls}, {score:.3f}"


def _known(value: object) -> bool:
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def _why(s: pd.Series, sigma: float, policy: StopPolicy) -> str:
    if _known(s.stop_step):
        window = "" if policy.n == 1 else f" ({policy.k} of the last {policy.n} frames reached their line)"
        if not _known(s.stop_level):
            house = " (no earlier frame: no house level yet)" if isinstance(policy, HouseStop) else ""
            return f"fired: {s.stop_score:.3f} reached sigma {sigma:g}{house}{window}"
        margin = policy.margin if isinstance(policy, HouseStop) else 0.0
        if s.stop_line == sigma:
            return (f"fired: {s.stop_score:.3f} reached sigma {sigma:g}, above level + margin "
                    f"({s.stop_level + margin:.3f}){window}")
        return f"fired: {s.stop_score:.3f} reached level {s.stop_level:.3f} + margin {margin:g}, above sigma{window}"
    if not _known(s.peak_step):
        return "never fired; the target is never in view"
    if s.peak_score < sigma:
        return f"never fired; the target's best {s.peak_score:.3f} is below sigma {sigma:g}"
    return f"never fired; the target's best {s.peak_score:.3f} is below its line (offset {s.peak_offset:.3f})"
