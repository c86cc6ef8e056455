"""What a matcher costs the agent: PIN's navigation metrics (SR, SPL, CE, D2G, Steps) estimated from recorded walks.

PIN judges a detection module by what its agent then does, and detection metrics can disagree
with it (the paper's DINO: the lowest CM, yet SR 4.02). Without a simulator, the walk a frame-set
recorded stands in for the agent's exploration: it is followed unchanged until the stop policy
fires on a frame whose matched points can be placed in the house (depth in PIN's sensor range);
the matched points are back-projected with the frame's depth, pose and camera, and the agent walks
toward their median (the goal point: the shortest walk on the floor map where there is one, around
walls, else straight) and stops where an agent of PIN's radius can stand:
on the floor, on the standable cell nearest the goal point where the frame-set has a floor map
(``FloorMap.stand``), else on the floor below the goal point pulled back toward the agent by its
radius and ``STAND_MARGIN``. Every outcome is measured from where the agent stands, on the floor,
as PIN measures it (the Euclidean distance from the agent's position to the target's): success
within PIN's success distance of the target; category error within it of a same-category
look-alike instead; D2G its distance to the target; Steps the actions walked to the stop frame,
the turns and forward steps to the standing point, and the stop; SPL success x geodesic /
max(path, geodesic). A walk on which the policy never commits is "not found": it never fired on
a placeable frame, or its window was still open when the walk ended (still looking: its
``fired_step`` is set); a failure, D2G from where the agent stands at the walk's end, Steps the
walk's. Assumptions and the paper's definitions: docs/metrics.md, "Navigation".

Pure functions of a score table, its frame-set (geometry, depth, masks) and a stop policy;
``Placements`` reads each frame's depth at its points once and serves every sigma.
"""

from __future__ import annotations

import math
import weakref

import numpy as np
import pandas as pd

from pin_match.data.agent import FORWARD_STEP, MAX_STEPS, TURN
from pin_match.data.geometry import AGENT_RADIUS, EpisodeGeometry
from pin_match.evaluation.core.intervals import Clusters, per_episode_intervals
from pin_match.evaluation.core.metrics import DEFAULT_BOOT, Bootstrap, to_python
from pin_match.evaluation.core.placements import NavigationError, Placements
from pin_match.evaluation.core.stop import (
    FIRST_MATCH,
    ApproachVerify,
    CloseLook,
    Decision,
    StopPolicy,
    Verify,
    episode_bounds,
)

SUCCESS_DISTANCE = 1.0  # metres: PIN's success (and category-error) radius
STAND_MARGIN = 0.1  # metres: without a floor map the agent stops this far beyond its radius short of the goal point
ABOUT_FACE = 6  # turns of 30 degrees: the agent turns back to its walk after rejecting a candidate (no floor map)

OUTCOMES = ("success", "category error", "other stop", "not found")
NAVIGATION_KEYS = ("sr", "spl", "ce", "d2g", "steps")  # PIN's column order
SHARE_KEYS = ("not_found_pct", "unplaced_pct")
EPISODE_SHARES = ("sr", "ce", *SHARE_KEYS)  # the % of episodes with a yes/no outcome (their intervals: intervals.py)
REJECTION_KEYS = ("rejections", "rejected_target_pct", "rejected_lookalike_pct", "rejected_other_pct",
                  "rejected_nothing_pct")
EPISODE_COLUMNS = ["episode_id", "target_object_id", "outcome", "stop_frame_id", "stop_step", "point_frame_id",
                   "landed_on", "point_x", "point_y", "point_z", "stand_x", "stand_y", "d2g", "path", "geodesic", "spl",
                   "steps", "unplaced_candidates", "fired_step", "candidates", "rejected", "rejected_target",
                   "rejected_lookalike", "rejected_other", "rejected_nothing", "rejections"]


Made = tuple[list[Decision], dict[int, tuple[np.ndarray, str] | None], Verify | None]  # ``walk_decisions``'
_LAST_DECIDED: weakref.WeakKeyDictionary[Placements, tuple[tuple[float, StopPolicy], Made]] = \
    weakref.WeakKeyDictionary()  # per placements, ``walk_decisions``' last, with its key


def episodes_at(places: Placements, sigma: float, policy: StopPolicy = FIRST_MATCH) -> pd.DataFrame:
    """One row per episode (``EPISODE_COLUMNS``): where the agent stopped, what it landed on, SR's and SPL's parts,
    and what an approach-verify policy rejected on its way (``walk_decisions``)."""
    decisions, placed, verify = walk_decisions(places, sigma, policy)
    rows = []
    for (start, end), decision in zip(episode_bounds(places.arrays), decisions):
        row = _episode(places, decision, start, end, placed, isinstance(policy, ApproachVerify))
        if isinstance(policy, ApproachVerify):
            row |= _rejections(places, policy, decision, placed, verify)  # type: ignore[arg-type]
        rows.append(row)
    return pd.DataFrame(rows, columns=EPISODE_COLUMNS)


def walk_decisions(places: Placements, sigma: float, policy: StopPolicy = FIRST_MATCH) -> Made:
    """The policy's decisions on the walks (``StopPolicy.decide``), a candidate placeable where its points at the
    frame's line have depth in range, an approach-verify policy's close looks from its walk-ups
    (``Placements.close_look``): an episode that walks up to a candidate whose views are not scored yet waits, the
    views every waiting episode asked for are rendered and scored together (``WalkUpViews.resolve``), and all decide
    again, until none waits; with the placed candidates and the close looks, for the rows built from them.
    The last one is kept per placements: a report's rows (``episodes_at``) and its commit table ask for the same
    decisions one after the other, and they are made once."""
    key = (float(sigma), policy)
    last = _LAST_DECIDED.get(places)
    if last is None or last[0] != key:
        last = _LAST_DECIDED[places] = key, _decide(places, sigma, policy)
    return last[1]


def _decide(places: Placements, sigma: float, policy: StopPolicy) -> Made:
    arr = places.arrays
    line = policy.line(arr, sigma)  # sigma, or the policy's per frame
    placed: dict[int, tuple[np.ndarray, str] | None] = {}

    def placeable(frame: int) -> bool:
        if frame not in placed:
            placed[frame] = places.place(places.frame_ids[frame], float(line[frame]))
        return placed[frame] is not None

    verify = _verifier(places, policy, placed)
    while True:  # a walk-up not rendered yet leaves its episode waiting: render and score them all, decide again
        decisions = policy.decide(arr, sigma, placeable, verify=verify)
        if verify is None or places.walkups is None:
            return decisions, placed, verify
        for (_, end), decision in zip(episode_bounds(arr), decisions):
            if decision.approaching is not None:
                _ask_ahead(arr.score >= line, decision.approaching, end, placeable, verify)
        if not places.walkups.resolve():
            return decisions, placed, verify


def _verifier(places: Placements, policy: StopPolicy,
              placed: dict[int, tuple[np.ndarray, str] | None]) -> Verify | None:
    """An approach-verify policy's close looks (None for any other policy); a set with nothing to walk up to says so."""
    if not isinstance(policy, ApproachVerify):
        return None
    if places.walkups is None and not places.recorded_views:
        raise NavigationError(f"stop policy {policy} walks up to each candidate, but {places.fs.root} has no "
                              "walk-ups: a synthetic set renders them when its matcher is given (pin-match tune / "
                              "report / bench / trade do), a PIN recording has the approach views it recorded, "
                              "and a set with neither cannot show what walking up would have seen")

    def verify(frame: int) -> CloseLook:
        return places.close_look(frame, placed[frame], policy.distance)  # type: ignore[arg-type]  # placed

    return verify


PREFETCH = 6  # an episode waiting on a walk-up asks for the next candidates' too: one round of rendering, not six


def _ask_ahead(counted: np.ndarray, waiting: int, end: int, placeable, verify: Verify) -> None:
    """Ask for the walk-ups of the next ``PREFETCH`` placeable candidates after ``waiting`` in its episode, which the
    agent walks up to if it rejects the one it waits on: computing ahead, never deciding ahead (a view asked for is
    read only when the decision reaches its candidate)."""
    ahead = [int(t) for t in np.flatnonzero(counted[waiting + 1:end]) + waiting + 1]
    for frame in [t for t in ahead if placeable(t)][:PREFETCH]:
        verify(frame)


def _rejections(places: Placements, policy: ApproachVerify, decision: Decision,
                placed: dict[int, tuple[np.ndarray, str] | None], verify: Verify) -> dict:
    """What the agent walked up to and rejected: how many, of them targets and look-alikes, and each as
    ``step:what it landed on:close score``."""
    roles, texts = [], []
    for _, candidate in decision.rejected:
        role = placed[candidate][1]  # type: ignore[index]  # a rejected candidate was placed
        close = policy.close_score(verify(candidate), float(places.arrays.score[candidate]))
        roles.append(role)
        texts.append(f"{int(places.steps[candidate])}:{role}:{close:.3f}")
    return dict(rejected=len(roles), rejected_target=roles.count("target"),
                rejected_lookalike=roles.count("same_category"), rejected_other=roles.count("other"),
                rejected_nothing=roles.count("background"), rejections="; ".join(texts) or None)


def _episode(places: Placements, decision: Decision, start: int, end: int,
             placed: dict[int, tuple[np.ndarray, str] | None], walked_up: bool) -> dict:
    episode_id = str(places.arrays.episode_ids[places.arrays.episode[start]])
    geometry = places.geometry.episodes[episode_id]
    target_id = places.target[episode_id]
    if decision.chosen is not None:
        return _within_budget(_stop(places, geometry, episode_id, target_id, decision, placed, walked_up))
    last = end - 1
    target = np.asarray(geometry.positions[target_id])
    position = np.r_[places.xy[last], geometry.start.z]  # where it stands when the walk ends, on the floor
    detour_steps, detour_path = _detours(places, geometry, decision, placed)
    return _within_budget(dict(
        episode_id=episode_id, target_object_id=target_id, outcome="not found", stop_frame_id=None, stop_step=None,
        point_frame_id=None, landed_on=None, point_x=None, point_y=None, point_z=None, stand_x=float(position[0]),
        stand_y=float(position[1]), d2g=float(np.linalg.norm(position - target)),
        path=float(places.walked[last]) + detour_path, geodesic=geometry.geodesic_distance, spl=0.0,
        steps=int(places.steps[last]) + detour_steps, unplaced_candidates=decision.unplaced,
        fired_step=None if decision.fired is None else int(places.steps[decision.fired]),
        candidates=len(decision.candidates)))


def _within_budget(row: dict) -> dict:
    """PIN ends an episode after ``MAX_STEPS``: where the detours push the stop (or the walk's end) beyond it, the
    agent never stopped: not found, at ``MAX_STEPS`` steps (D2G stays where it was heading: the position at the
    limit itself is not modelled)."""
    if row["steps"] <= MAX_STEPS:
        return row
    return row | dict(outcome="not found", stop_frame_id=None, stop_step=None, landed_on=None, spl=0.0,
                      steps=MAX_STEPS)


def _stop(places: Placements, geometry: EpisodeGeometry, episode_id: str, target_id: str, decision: Decision,
          placed: dict[int, tuple[np.ndarray, str] | None], walked_up: bool) -> dict:
    """The walk from where the agent stopped looking (``decision.stop``) to where it stands beside the committed
    point (``_walk_to``), after the detours to every candidate it walked up to and rejected."""
    t, source = int(decision.stop), int(decision.chosen)  # type: ignore[arg-type]  # a committed decision
    point, landed_on = placed[source]  # type: ignore[misc]  # a committed candidate is placed
    walkup = places.walk_up(source, point) if walked_up else None
    if walkup is not None:  # it walked up to the candidate to check it: it stands where the walk-up ended
        stand, walked, actions = np.r_[walkup.end, geometry.start.z], walkup.walked, walkup.actions
    else:
        stand, walked, turns = _walk_to(places, geometry, t, point)
        actions = turns + math.ceil(walked / FORWARD_STEP)
    target = np.asarray(geometry.positions[target_id])
    d2g = float(np.linalg.norm(stand - target))
    same = [np.asarray(xyz) for oid, xyz in geometry.positions.items()
            if oid != target_id and places.category[oid] == places.category[target_id]]
    near_same = any(np.linalg.norm(stand - xyz) <= SUCCESS_DISTANCE for xyz in same)
    outcome = "success" if d2g <= SUCCESS_DISTANCE else "category error" if near_same else "other stop"
    detour_steps, detour_path = _detours(places, geometry, decision, placed)
    steps = int(places.steps[t]) + detour_steps + actions + 1
    path = float(places.walked[t]) + detour_path + walked
    geodesic = geometry.geodesic_distance
    spl = float(outcome == "success") * geodesic / max(path, geodesic) if max(path, geodesic) > 0 else 0.0
    return dict(episode_id=episode_id, target_object_id=target_id, outcome=outcome,
                stop_frame_id=str(places.frame_ids[t]), stop_step=int(places.steps[t]),
                point_frame_id=str(places.frame_ids[source]), landed_on=landed_on, point_x=float(point[0]),
                point_y=float(point[1]), point_z=float(point[2]), stand_x=float(stand[0]), stand_y=float(stand[1]),
                d2g=d2g, path=path, geodesic=geodesic, spl=spl,
                steps=steps, unplaced_candidates=decision.unplaced,
                fired_step=int(places.steps[int(decision.fired)]),
                candidates=len(decision.candidates))


def _walk_to(places: Placements, geometry: EpisodeGeometry, t: int, point: np.ndarray) -> tuple[np.ndarray, float,
                                                                                                  int]:
    """From where the agent stands at frame ``t`` to where it stands beside ``point``: the standing point, the
    metres walked (the shortest walk on the episode's floor map, around walls and furniture, ``FloorMap.walk_length``;
    the straight line without one) and the turns toward the straight heading."""
    key = (t, np.asarray(point, np.float64).tobytes())  # a sweep meets the same walk at many sigmas
    if key not in places.walks:
        places.walks[key] = _walk_from(places, geometry, t, point)
    return places.walks[key]


def _walk_from(places: Placements, geometry: EpisodeGeometry, t: int, point: np.ndarray) -> tuple[np.ndarray, float,
                                                                                                    int]:
    stand = standing_point(geometry, point, places.xy[t])
    ahead = stand[:2] - places.xy[t]
    distance = float(np.hypot(*ahead))
    heading = math.atan2(ahead[1], ahead[0]) if distance > 1e-9 else float(places.yaw[t])
    turn = abs((heading - places.yaw[t] + math.pi) % (2 * math.pi) - math.pi)
    turns = max(0, math.ceil((turn - TURN / 2) / TURN - 1e-9))  # until the point is within half a turn of the heading
    walked = distance if geometry.floor_map is None else geometry.floor_map.walk_length(places.xy[t], stand[:2])
    return stand, walked, turns


def _detours(places: Placements, geometry: EpisodeGeometry, decision: Decision,
             placed: dict[int, tuple[np.ndarray, str] | None]) -> tuple[int, float]:
    """Steps and metres of the round trips to the candidates the agent walked up to and rejected: the walk-up's
    actions and the walk back (``WalkUp.back``) where the episode has a floor map; else the turns toward the
    candidate, the straight walk there and back and an about-turn (``ABOUT_FACE``)."""
    steps, path = 0, 0.0
    for left_at, candidate in decision.rejected:
        goal = placed[candidate][0]  # type: ignore[index]  # a rejected candidate was placed
        walkup = places.walk_up(candidate, goal)
        if walkup is not None:
            steps += walkup.actions + walkup.back
            path += 2 * walkup.walked
            continue
        _, walked, turns = _walk_to(places, geometry, left_at, goal)
        steps += turns + 2 * math.ceil(walked / FORWARD_STEP) + ABOUT_FACE
        path += 2 * walked
    return steps, path


def standing_point(geometry: EpisodeGeometry, goal: np.ndarray, eye_xy: np.ndarray) -> np.ndarray:
    """Where an agent at ``eye_xy`` (x, y) that walks to the goal point stops, on the floor: the standable cell
    nearest the goal on the episode's floor map; without a map, the floor below the goal pulled back toward the
    agent by its radius and ``STAND_MARGIN`` (where it stands already when the goal is nearer than that)."""
    goal_xy, eye_xy = np.asarray(goal[:2], np.float64), np.asarray(eye_xy[:2], np.float64)
    if geometry.floor_map is not None:
        xy = geometry.floor_map.stand(goal_xy, eye_xy)
    else:
        back = AGENT_RADIUS + STAND_MARGIN
        ahead = goal_xy - eye_xy
        distance = float(np.hypot(*ahead))
        xy = eye_xy if distance <= back else goal_xy - ahead / distance * back
    return np.r_[xy, geometry.start.z]


def metrics_of(episodes: pd.DataFrame, weights: np.ndarray | None = None) -> dict[str, float]:
    """SR, SPL, CE (% of episodes), D2G (metres), Steps, the shares not found and with an unplaced candidate, and of
    an approach-verify policy the candidates rejected per episode and the % of them that were the target, a
    look-alike, another annotated object or nothing annotated (NaN where none was rejected; ``REJECTION_KEYS``, only
    for an approach-verify policy's rows), each episode counted ``weights`` times (None: once)."""
    w = np.ones(len(episodes)) if weights is None else np.asarray(weights, np.float64)
    total = w.sum()
    if not total:
        return {k: math.nan for k in (*NAVIGATION_KEYS, *SHARE_KEYS)}

    def mean(values) -> float:
        return float(np.dot(w, np.asarray(values, np.float64)) / total)

    outcome = episodes["outcome"]
    rejected = np.dot(w, episodes["rejected"].fillna(0).to_numpy(np.float64))

    def rejected_share(column: str) -> float:
        return float(100 * np.dot(w, episodes[column].fillna(0).to_numpy(np.float64)) / rejected) if rejected \
            else math.nan

    out = dict(sr=100 * mean(outcome == "success"), spl=100 * mean(episodes["spl"]),
               ce=100 * mean(outcome == "category error"), d2g=mean(episodes["d2g"]), steps=mean(episodes["steps"]),
               not_found_pct=100 * mean(outcome == "not found"),
               unplaced_pct=100 * mean(episodes["unplaced_candidates"] > 0))
    if episodes["rejected"].notna().any():  # an approach-verify policy's rows
        out |= dict(rejections=float(rejected / total), rejected_target_pct=rejected_share("rejected_target"),
                    rejected_lookalike_pct=rejected_share("rejected_lookalike"),
                    rejected_other_pct=rejected_share("rejected_other"),
                    rejected_nothing_pct=rejected_share("rejected_nothing"))
    return out


def navigation_metrics(episodes: pd.DataFrame, clusters: Clusters | None = None,
                       boot: Bootstrap = DEFAULT_BOOT) -> dict:
    """``metrics_of`` with percentile intervals resampling target instances (``clusters``), as every other metric."""
    point, ci = per_episode_intervals(episodes, metrics_of, clusters, boot, shares=EPISODE_SHARES)
    return dict(metrics={k: to_python(v) for k, v in point.items()}, ci95=ci, n_episodes=len(episodes),
                outcomes={o: int((episodes["outcome"] == o).sum()) for o in OUTCOMES})


def navigation_sweep(places: Placements, sigmas: np.ndarray, policy: StopPolicy = FIRST_MATCH) -> pd.DataFrame:
    """``metrics_of`` at each sigma (ascending): the curve the plots draw and the SR objective reads."""
    rows = [{"sigma": float(s), **metrics_of(episodes_at(places, float(s), policy))} for s in sigmas]
    return pd.DataFrame(rows, columns=["sigma", *NAVIGATION_KEYS, *SHARE_KEYS, *REJECTION_KEYS])


MAX_SWEEP_SIGMAS = 200  # a navigation curve places each episode's stop anew per sigma: quantiles beyond this many
WALK_UP_SIGMAS = np.linspace(0.85, 0.995, 5)  # an approach-verify policy renders and scores the walk-ups of each
# sigma's firings: its curve reads these quantiles of the scores only (its sigma sits high: a firing costs a detour)


def sweep_sigmas(scores: np.ndarray, policy: StopPolicy = FIRST_MATCH) -> np.ndarray:
    """Candidate sigmas for a navigation curve: every distinct score, or ``MAX_SWEEP_SIGMAS`` quantiles of them; for
    an approach-verify policy the ``WALK_UP_SIGMAS`` quantiles."""
    values = np.unique(np.asarray(scores, np.float64))
    if isinstance(policy, ApproachVerify) and len(values):
        return np.unique(np.quantile(np.asarray(scores, np.float64), WALK_UP_SIGMAS, method="lower"))
    if len(values) > MAX_SWEEP_SIGMAS:
        values = np.unique(np.quantile(values, np.linspace(0.0, 1.0, MAX_SWEEP_SIGMAS), method="lower"))
    return values
