"""How far one sigma carries: chosen on some frame-sets, read on one that nobody tuned it on.

A PIN agent runs one sigma in a house nobody tuned it on, so a set's own best sigma flatters a
matcher: the figure that matters is what a sigma chosen elsewhere gives there. ``carried`` reads
a sigma on a set beside that set's own best (PIN's first-match objective): CM (share of matched
frames that show a look-alike) and first-match precision, with intervals over target instances.
``leave_one_out`` chooses sigma on every set but one, reads it on the one left out, for each set
in turn; its worst row (highest CM, widest first-match gap) is how far the score carries.
``chosen_and_carried`` does the same for a choice among variants of a matcher (a config value,
e.g. the cohort's ``k``, or a stop policy and its parameters): for each set left out, the variant is
chosen on the other sets alone (leaving one out among them), so neither sigma nor variant has seen
the set it is read on. A stop policy (``stop``) is read the same way: sigma chosen for it on the
other sets, its found frames read on the set, beside the set's own best sigma under PIN's rule
(the one reference every policy is measured against); on a set with geometry the navigation
estimate's SR and CE (``navigation``) at both.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from pin_match.errors import PinMatchError
from pin_match.evaluation.core.commits import commit_shares, commitments
from pin_match.evaluation.core.intervals import bootstrap_ci
from pin_match.evaluation.core.metrics import (
    DEFAULT_BOOT,
    Bootstrap,
    FrameArrays,
    frame_arrays,
    ranking_metrics,
    threshold_metrics,
)
from pin_match.evaluation.core.navigation import episodes_at, metrics_of
from pin_match.evaluation.core.placements import Placements
from pin_match.evaluation.core.policies import policy_sigma
from pin_match.evaluation.core.stop import FIRST_MATCH, StopPolicy, fired_arrays, found_frames
from pin_match.evaluation.core.tuning import sigma_for


class CarryError(PinMatchError, ValueError):
    """Too few sets to leave one out, or a set with no frames to tune or read."""


@dataclass(frozen=True)
class ScoredSet:
    """One frame-set's scored frames (``EvalContext.scored``): those sigma is tuned on (its train split, or all of
    it) and those it is read on (its val split, or all of it), and each episode's target instance."""

    tuning: pd.DataFrame
    reading: pd.DataFrame
    clusters: dict[str, str]
    placements: Placements | None = None  # the reading frames placed in the house (``navigation``), with geometry


def carried(frames: pd.DataFrame, sigma: float, clusters: dict[str, str], boot: Bootstrap = DEFAULT_BOOT,
            policy: StopPolicy = FIRST_MATCH, placements: Placements | None = None) -> dict:
    """``frames`` read at ``sigma`` under ``policy`` beside their own best sigma under PIN's rule: AUROC-same, CM and
    first-match precision with intervals (target instances resampled), %Match and first-match success (% of all
    episodes whose first match is the target, what sigma is chosen by) at both, so a sigma that keeps CM low by
    matching in few episodes shows; the first-match gaps (own best minus carried, in points, of precision and of
    success); with ``placements`` (the frames placed in their house) SR and CE at both (else NaN); what the policy
    commits to (``committed_at``). A metric undefined at a sigma (nothing matched) is NaN."""
    arrays = frame_arrays(frames)
    own, at, at_own = readings(arrays, frames, sigma, policy)
    fired = fired_arrays(arrays, found_frames(arrays, sigma, policy))
    ci = bootstrap_ci(fired, 0.5, clusters=clusters, boot=boot) | \
        {"auroc_same": bootstrap_ci(arrays, sigma, clusters=clusters, boot=boot)["auroc_same"]}
    low_high = {key: ci[key] or [np.nan, np.nan] for key in ("auroc_same", "cm_pct", "first_match_precision")}
    ranking = ranking_metrics(arrays)
    walk = navigation_at(placements, sigma, policy, own)
    commit = committed_at(arrays, frames, sigma, policy)
    row = dict(auroc_same=ranking["auroc_same"], auroc_target=ranking["auroc_target"],
               auroc_low=low_high["auroc_same"][0], auroc_high=low_high["auroc_same"][1],
               sigma=sigma, tm=at["tm_pct"], cm=at["cm_pct"], cm_low=low_high["cm_pct"][0],
               cm_high=low_high["cm_pct"][1], match=at["match_pct"], first_precision=at["first_match_precision"],
               first_low=low_high["first_match_precision"][0], first_high=low_high["first_match_precision"][1],
               first_success=at["first_match_success"], own_sigma=own, own_cm=at_own["cm_pct"],
               own_match=at_own["match_pct"], own_first_precision=at_own["first_match_precision"],
               own_first_success=at_own["first_match_success"], **walk, **commit)
    row = {key: float(value) for key, value in row.items()}
    return dict(row, first_gap=row["own_first_precision"] - row["first_precision"],
                success_gap=row["own_first_success"] - row["first_success"])


def committed_at(arrays: FrameArrays, frames: pd.DataFrame, sigma: float, policy: StopPolicy) -> dict[str, float]:
    """What ``policy`` commits to at ``sigma`` (% of all episodes: to the target, to a look-alike; frames looked at),
    and the share committed to the target at the set's own best sigma for the same policy (first-match objective on
    these frames), with the gap between the two in points."""
    at = commit_shares(commitments(arrays, sigma, policy))
    best = commit_shares(commitments(arrays, policy_sigma(frames, policy), policy))
    return dict(commit_target=at["commit_target_pct"], commit_lookalike=at["commit_lookalike_pct"],
                looked=at["frames_looked_at"], own_commit_target=best["commit_target_pct"],
                commit_gap=best["commit_target_pct"] - at["commit_target_pct"])


def readings(arrays: FrameArrays, frames: pd.DataFrame, sigma: float,
             policy: StopPolicy = FIRST_MATCH) -> tuple[float, dict, dict]:
    """The set's own best sigma under PIN's rule, every threshold metric under ``policy`` at ``sigma``, and under PIN's
    rule at its own best (NaN where undefined): what a carried row is read from."""
    own = sigma_for(frames)
    at = threshold_metrics(fired_arrays(arrays, found_frames(arrays, sigma, policy)), 0.5)
    return own, at, threshold_metrics(arrays, own)


def navigation_at(placements: Placements | None, sigma: float, policy: StopPolicy, own: float) -> dict[str, float]:
    """SR and CE of the navigation estimate under ``policy`` at ``sigma`` and under PIN's rule at ``own``; NaN
    without placements (a set without geometry)."""
    if placements is None:
        return dict(sr=math.nan, ce=math.nan, own_sr=math.nan, own_ce=math.nan)
    at, at_own = metrics_of(episodes_at(placements, sigma, policy)), metrics_of(episodes_at(placements, own))
    return dict(sr=at["sr"], ce=at["ce"], own_sr=at_own["sr"], own_ce=at_own["ce"])


def pooled(frames: list[pd.DataFrame]) -> pd.DataFrame:
    """Several sets' scored frames as one, ids kept apart (two variants of one source share frame ids)."""
    return pd.concat([f.assign(frame_id=lambda t, i=i: f"{i}:" + t.frame_id,
                               episode_id=lambda t, i=i: f"{i}:" + t.episode_id) for i, f in enumerate(frames)],
                     ignore_index=True)


def sigma_without(sets: Mapping[str, ScoredSet], name: str, policy: StopPolicy = FIRST_MATCH) -> float:
    """Sigma chosen for ``policy`` (first-match objective) on the tuning frames of every set but ``name``, pooled (no
    house: an approach-verify policy, which walks up to its candidates in one, is refused by ``policy_sweep``)."""
    others = [s.tuning for other, s in sets.items() if other != name]
    if not others or any(f.empty for f in others) or sets[name].reading.empty:
        raise CarryError(f"a frame-set has no scored frames to tune or read (left out: {name})")
    return policy_sigma(pooled(others), policy)


def carried_without(sets: Mapping[str, ScoredSet], name: str, boot: Bootstrap = DEFAULT_BOOT,
                    policy: StopPolicy = FIRST_MATCH) -> dict:
    """``carried`` for set ``name``: sigma chosen for ``policy`` on every other set, read on this one."""
    held_out = sets[name]
    return carried(held_out.reading, sigma_without(sets, name, policy), held_out.clusters, boot, policy,
                   held_out.placements)


def leave_one_out(sets: Mapping[str, ScoredSet], boot: Bootstrap = DEFAULT_BOOT,
                  policy: StopPolicy = FIRST_MATCH) -> pd.DataFrame:
    """One row per set: sigma chosen for ``policy`` on every other set's tuning frames together, read on this set's
    frames (``carried``); the rows sorted worst first (``worst_first``)."""
    if len(sets) < 2:
        raise CarryError(f"leaving one set out needs at least two frame-sets, got {len(sets)}")
    return worst_first(pd.DataFrame([dict(set=name, **carried_without(sets, name, boot, policy)) for name in sets]))


def worst_first(rows: pd.DataFrame) -> pd.DataFrame:
    """A set where the carried sigma matches nothing (CM undefined) first, then the highest CM."""
    return rows.sort_values("cm", ascending=False, na_position="first").reset_index(drop=True)


def carry_risk(sets: Mapping[str, ScoredSet], policy: StopPolicy = FIRST_MATCH) -> tuple[float, float, float]:
    """(worst CM, largest first-match precision gap, largest first-match success gap) of leaving each set out in turn
    under ``policy``, point values: what a variant is chosen by, in that order (the success gap breaks ties, so
    matching in fewer episodes does not win them). A carried sigma that matches nothing on a set counts as the worst
    CM and precision gap there are (infinity)."""
    worst_cm = worst_gap = worst_success = -np.inf
    for name, held_out in sets.items():
        frames = held_out.reading
        _, at, own = readings(frame_arrays(frames), frames, sigma_without(sets, name, policy), policy)
        cm, gap = at["cm_pct"], own["first_match_precision"] - at["first_match_precision"]
        worst_cm = max(worst_cm, np.inf if math.isnan(cm) else cm)
        worst_gap = max(worst_gap, np.inf if math.isnan(gap) else gap)
        worst_success = max(worst_success, own["first_match_success"] - at["first_match_success"])
    return float(worst_cm), float(worst_gap), float(worst_success)


def chosen_and_carried(variants: Mapping[str, Mapping[str, ScoredSet]], boot: Bootstrap = DEFAULT_BOOT,
                       policies: Mapping[str, StopPolicy] | None = None) -> pd.DataFrame:
    """One row per set: the variant chosen on the other sets alone (lowest ``carry_risk`` among them: worst CM, then
    the largest first-match precision gap, then success gap; the first listed on a tie), its sigma chosen on those
    sets, read on this set
    (``carried``); worst first. ``variants``: per variant name, the same sets scored by it; ``policies``: per
    variant name, the stop policy it is read with (default PIN's rule for every one)."""
    names = [list(sets) for sets in variants.values()]
    if not names or any(n != names[0] for n in names):
        raise CarryError("every variant must be scored on the same frame-sets")
    if len(names[0]) < 3:
        raise CarryError(f"choosing a variant without the set left out needs at least three frame-sets, "
                         f"got {len(names[0])}")
    policy = {v: (policies or {}).get(v, FIRST_MATCH) for v in variants}
    rows = []
    for name in names[0]:
        risks = {v: carry_risk({n: s for n, s in sets.items() if n != name}, policy[v]) for v, sets in variants.items()}
        chosen = min(risks, key=risks.get)
        rows.append(dict(set=name, variant=chosen, chosen_by_cm=risks[chosen][0], chosen_by_gap=risks[chosen][1],
                         chosen_by_success_gap=risks[chosen][2],
                         **carried_without(variants[chosen], name, boot, policy[chosen])))
    return worst_first(pd.DataFrame(rows))


def headline(rows: pd.DataFrame) -> dict:
    """How far a score carries over these rows: the worst CM and its set, the largest first-match precision gap and
    success gap with their sets, the lowest %Match, the mean AUROC-same; where sets have geometry, the lowest SR and
    the highest CE (NaN where none has); the highest share of episodes committed to a look-alike and the largest
    gap to the set's own best share committed to the target."""
    ranked = worst_first(rows)
    gaps, success = rows.first_gap.fillna(np.inf), rows.success_gap.fillna(np.inf)
    walks = rows.dropna(subset=["sr"]) if "sr" in rows else rows.iloc[:0]
    return dict(worst_cm=float(ranked.cm.iloc[0]), worst_cm_set=str(ranked.set.iloc[0]),
                largest_gap=float(rows.first_gap[gaps.idxmax()]), largest_gap_set=str(rows.set[gaps.idxmax()]),
                largest_success_gap=float(rows.success_gap[success.idxmax()]),
                largest_success_gap_set=str(rows.set[success.idxmax()]), lowest_match=float(rows.match.min()),
                mean_auroc_same=float(rows.auroc_same.mean()),
                lowest_sr=float(walks.sr.min()) if len(walks) else math.nan,
                highest_ce=float(walks.ce.max()) if len(walks) else math.nan,
                worst_commit_lookalike=float(rows.commit_lookalike.max()),
                largest_commit_gap=float(rows.commit_gap.max()))
