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
from dataclasses import dataclass

import numpy as np
import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.data.geometry import AGENT_RADIUS, EpisodeGeometry, Geometry
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.intervals import Clusters, per_episode_intervals
from pin_match.evaluation.core.metrics import DEFAULT_BOOT, Bootstrap, FrameArrays, to_python
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
FORWARD_STEP = 0.25  # metres per forward action
TURN = math.radians(30.0)  # one turn action
DEPTH_RANGE = (0.5, 5.0)  # PIN's depth sensor, metres: below the first or at the second a pixel has no depth
STAND_MARGIN = 0.1  # metres: without a floor map the agent stops this far beyond its radius short of the goal point
ON_OBJECT = 0.5  # metres: a goal point this near an object's centre is on it (its approach views are the close look)
REMEMBERED_CELL = 0.5  # metres: a rejected goal on no object is remembered as its floor cell of this size
ABOUT_FACE = 6  # turns of 30 degrees: the agent turns back to its walk after rejecting a candidate
MAX_STEPS = 1000  # PIN's episode ends here: a stop not called within this many steps is no stop

OUTCOMES = ("success", "category error", "other stop", "not found")
NAVIGATION_KEYS = ("sr", "spl", "ce", "d2g", "steps")  # PIN's column order
SHARE_KEYS = ("not_found_pct", "unplaced_pct")
EPISODE_SHARES = ("sr", "ce", *SHARE_KEYS)  # the % of episodes with a yes/no outcome (their intervals: intervals.py)
REJECTION_KEYS = ("rejections", "rejected_target_pct", "rejected_lookalike_pct")
EPISODE_COLUMNS = ["episode_id", "target_object_id", "outcome", "stop_frame_id", "stop_step", "point_frame_id",
                   "landed_on", "point_x", "point_y", "point_z", "stand_x", "stand_y", "d2g", "path", "geodesic", "spl",
                   "steps", "unplaced_candidates", "fired_step", "candidates", "rejected", "rejected_target",
                   "rejected_lookalike", "rejections"]


class NavigationError(PinMatchError, ValueError):
    """A frame-set or score table on which the navigation estimate cannot be made."""


@dataclass(frozen=True)
class FramePoints:
    """One frame's stored points with what placing them needs: their scores, house-frame positions (NaN where the
    depth is outside PIN's range) and what each landed on in the instance mask."""

    scores: np.ndarray  # (K,)
    xyz: np.ndarray  # (K, 3)
    roles: np.ndarray  # (K,) object role at the point's pixel, "background" where none


class Placements:
    """A scored split's frames in walk order, with each frame's points placed in the house on first use.

    Built once per (table, split) and asked at any sigma, so a sweep reads each frame's depth once.
    """

    def __init__(self, fs: FrameSet, scored: pd.DataFrame, arr: FrameArrays, table_frames: pd.DataFrame,
                 approach: pd.DataFrame | None = None) -> None:
        reason = fs.navigation_missing
        if reason is not None:
            raise NavigationError(f"no navigation estimate on {fs.root}: {reason}")
        self.fs = fs
        self.geometry: Geometry = fs.geometry  # type: ignore[assignment]  # present: navigation_missing is None
        codes = pd.factorize(scored["episode_id"], sort=False)[0]
        order = np.lexsort((scored["step"].to_numpy(), codes))  # the order of ``metrics.frame_arrays``
        self.frame_ids = scored["frame_id"].to_numpy()[order]
        self.steps = scored["step"].to_numpy(np.int64)[order]
        self.arrays = arr  # the same frames in the same order: the stop policy reads its scores
        self.rows = table_frames.set_index("frame_id")
        poses = self.geometry.poses.loc[self.frame_ids]
        self.xy = poses[["pose_x", "pose_y"]].to_numpy(np.float64)
        self.yaw = poses["pose_yaw"].to_numpy(np.float64)
        moved = np.r_[0.0, np.hypot(*np.diff(self.xy, axis=0).T)]
        moved[np.r_[True, np.diff(arr.episode) != 0]] = 0.0
        self.walked = _cumsum_by_episode(moved, arr.episode)  # metres walked up to each frame
        self._points: dict[str, FramePoints] = {}
        self._roles = _role_values(fs)
        # read per stop at every sigma of a sweep: looked up in dicts, not in the tables
        self.category = dict(zip(fs.objects.object_id, fs.objects.category.astype(str)))
        self.target = dict(zip(fs.episodes.episode_id, fs.episodes.target_object_id.astype(str)))
        self.views = _approach_views(fs, approach)
        self.walks: dict[tuple[int, bytes], tuple[np.ndarray, float, int]] = {}  # ``_walk_to``'s, by frame and point
        self.decided: tuple[tuple[float, StopPolicy], Made] | None = None  # ``walk_decisions``' last, with its key

    def close_look(self, frame: int, placed: tuple[np.ndarray, str]) -> CloseLook:
        """Frame ``frame``'s candidate, placed at ``placed``'s goal point, as an agent walking up to it meets it: the
        approach views of the object the goal is on (its centre within ``ON_OBJECT``), remembered as that object;
        a goal on no such object has no views and is remembered as its floor cell."""
        episode_id = str(self.arrays.episode_ids[self.arrays.episode[frame]])
        goal = placed[0]
        positions = self.geometry.episodes[episode_id].positions
        if positions:
            ids = list(positions)
            gaps = np.linalg.norm(np.asarray([positions[i] for i in ids], np.float64) - goal, axis=1)
            nearest = int(np.argmin(gaps))
            if gaps[nearest] <= ON_OBJECT:
                return CloseLook(ids[nearest], self.views.get((episode_id, ids[nearest]), ()))
        return CloseLook(("cell", *np.floor(goal[:2] / REMEMBERED_CELL).astype(int).tolist()))

    def points(self, frame_id: str) -> FramePoints:
        if frame_id not in self._points:
            row = self.rows.loc[frame_id]
            xy = np.stack([np.asarray(row["points_x"], np.float64), np.asarray(row["points_y"], np.float64)], 1)
            depth, mask = self.fs.depth(frame_id), self.fs.instance_mask(frame_id)
            px = np.clip(np.floor(xy[:, 0]).astype(np.int64), 0, depth.shape[1] - 1)
            py = np.clip(np.floor(xy[:, 1]).astype(np.int64), 0, depth.shape[0] - 1)
            d = depth[py, px].astype(np.float64)
            xyz = self.geometry.back_project(frame_id, xy, d)
            xyz[(d < DEPTH_RANGE[0]) | (d >= DEPTH_RANGE[1])] = np.nan  # a clipping sensor puts its far pixels at 5 m
            roles = self._roles.get(frame_id, {})
            self._points[frame_id] = FramePoints(np.asarray(row["point_scores"], np.float64), xyz,
                                                 np.array([roles.get(int(v), "background") for v in mask[py, px]],
                                                          dtype=object))
        return self._points[frame_id]

    def place(self, frame_id: str, sigma: float) -> tuple[np.ndarray, str] | None:
        """Where the agent would walk from this matched frame: the median of its placeable points at sigma, and
        what the point nearest it landed on; None when no point above sigma has depth in PIN's range."""
        p = self.points(frame_id)
        keep = (p.scores >= sigma) & ~np.isnan(p.xyz[:, 0])
        if not keep.any():
            return None
        xyz = p.xyz[keep]
        goal = np.median(xyz, axis=0)
        return goal, str(p.roles[keep][int(np.argmin(np.linalg.norm(xyz - goal, axis=1)))])


def _approach_views(fs: FrameSet, approach: pd.DataFrame | None) -> dict[tuple[str, str], tuple]:
    """Per (episode, object), its scored approach views as (distance, score), far to near."""
    if approach is None or approach.empty:
        return {}
    rows = fs.approach_views.set_index("frame_id").loc[approach.frame_id, ["approach_of", "approach_distance", "step"]]
    table = pd.DataFrame({"episode_id": approach.episode_id.to_numpy(), "object_id": rows.approach_of.to_numpy(),
                          "distance": rows.approach_distance.to_numpy(np.float64),
                          "score": approach.score.to_numpy(np.float64), "step": rows.step.to_numpy()})
    return {(str(e), str(o)): tuple(zip(group.distance.tolist(), group.score.tolist()))
            for (e, o), group in table.sort_values("step").groupby(["episode_id", "object_id"], sort=False)}


def _cumsum_by_episode(values: np.ndarray, episode: np.ndarray) -> np.ndarray:
    total = np.cumsum(values)
    starts = np.flatnonzero(np.r_[True, np.diff(episode) != 0]) if len(values) else np.zeros(0, np.int64)
    before = np.r_[0.0, total][starts]
    return total - np.repeat(before, np.diff(np.r_[starts, len(values)]))


def _role_values(fs: FrameSet) -> dict[str, dict[int, str]]:
    vis = fs.visibility
    out: dict[str, dict[int, str]] = {}
    for frame_id, value, role in zip(vis.frame_id, vis.mask_value, vis.role):
        out.setdefault(frame_id, {})[int(value)] = role
    return out


Made = tuple[list[Decision], dict[int, tuple[np.ndarray, str] | None], Verify | None]  # ``walk_decisions``'


def episodes_at(places: Placements, sigma: float, policy: StopPolicy = FIRST_MATCH) -> pd.DataFrame:
    """One row per episode (``EPISODE_COLUMNS``): where the agent stopped, what it landed on, SR's and SPL's parts,
    and what an approach-verify policy rejected on its way (``walk_decisions``)."""
    decisions, placed, verify = walk_decisions(places, sigma, policy)
    rows = []
    for (start, end), decision in zip(episode_bounds(places.arrays), decisions):
        row = _episode(places, decision, start, end, placed)
        if isinstance(policy, ApproachVerify):
            row |= _rejections(places, policy, decision, placed, verify)  # type: ignore[arg-type]
        rows.append(row)
    return pd.DataFrame(rows, columns=EPISODE_COLUMNS)


def walk_decisions(places: Placements, sigma: float, policy: StopPolicy = FIRST_MATCH) -> Made:
    """The policy's decisions on the walks (``StopPolicy.decide``), a candidate placeable where its points at the
    frame's line have depth in range, an approach-verify policy's close looks read from the approach views
    (``Placements.close_look``); with the placed candidates and the close looks, for the rows built from them.
    The last one is kept on ``places``: a report's rows (``episodes_at``) and its commit table ask for the same
    decisions one after the other, and they are made once."""
    key = (float(sigma), policy)
    if places.decided is None or places.decided[0] != key:
        places.decided = key, _decide(places, sigma, policy)
    return places.decided[1]


def _decide(places: Placements, sigma: float, policy: StopPolicy) -> Made:
    arr = places.arrays
    line = policy.line(arr, sigma)  # sigma, or the policy's per frame
    placed: dict[int, tuple[np.ndarray, str] | None] = {}

    def placeable(frame: int) -> bool:
        if frame not in placed:
            placed[frame] = places.place(places.frame_ids[frame], float(line[frame]))
        return placed[frame] is not None

    verify: Verify | None = None
    if isinstance(policy, ApproachVerify):
        def verify(frame: int) -> CloseLook:
            return places.close_look(frame, placed[frame])  # type: ignore[arg-type]  # a verified candidate is placed

    return policy.decide(arr, sigma, placeable, verify=verify), placed, verify


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
                rejected_lookalike=roles.count("same_category"), rejections="; ".join(texts) or None)


def _episode(places: Placements, decision: Decision, start: int, end: int,
             placed: dict[int, tuple[np.ndarray, str] | None]) -> dict:
    episode_id = str(places.arrays.episode_ids[places.arrays.episode[start]])
    geometry = places.geometry.episodes[episode_id]
    target_id = places.target[episode_id]
    if decision.chosen is not None:
        return _within_budget(_stop(places, geometry, episode_id, target_id, decision, placed))
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
          placed: dict[int, tuple[np.ndarray, str] | None]) -> dict:
    """The walk from where the agent stopped looking (``decision.stop``) to where it stands beside the committed
    point (``_walk_to``), after the detours to every candidate it walked up to and rejected."""
    t, source = int(decision.stop), int(decision.chosen)  # type: ignore[arg-type]  # a committed decision
    point, landed_on = placed[source]  # type: ignore[misc]  # a committed candidate is placed
    stand, walked, turns = _walk_to(places, geometry, t, point)
    target = np.asarray(geometry.positions[target_id])
    d2g = float(np.linalg.norm(stand - target))
    same = [np.asarray(xyz) for oid, xyz in geometry.positions.items()
            if oid != target_id and places.category[oid] == places.category[target_id]]
    near_same = any(np.linalg.norm(stand - xyz) <= SUCCESS_DISTANCE for xyz in same)
    outcome = "success" if d2g <= SUCCESS_DISTANCE else "category error" if near_same else "other stop"
    detour_steps, detour_path = _detours(places, geometry, decision, placed)
    steps = int(places.steps[t]) + detour_steps + turns + math.ceil(walked / FORWARD_STEP) + 1
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
    """Steps and metres of the round trips to the candidates the agent walked up to and rejected: to each and back
    to where it left its walk, turning about (``ABOUT_FACE``) in between."""
    steps, path = 0, 0.0
    for left_at, candidate in decision.rejected:
        _, walked, turns = _walk_to(places, geometry, left_at, placed[candidate][0])  # type: ignore[index]
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
    an approach-verify policy the candidates rejected per episode and the % of them that were the target or a
    look-alike (NaN where none was rejected; these three only for an approach-verify policy's rows), each episode
    counted ``weights`` times (None: once)."""
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
                    rejected_lookalike_pct=rejected_share("rejected_lookalike"))
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


def sweep_sigmas(scores: np.ndarray) -> np.ndarray:
    """Candidate sigmas for a navigation curve: every distinct score, or ``MAX_SWEEP_SIGMAS`` quantiles of them."""
    values = np.unique(np.asarray(scores, np.float64))
    if len(values) > MAX_SWEEP_SIGMAS:
        values = np.unique(np.quantile(values, np.linspace(0.0, 1.0, MAX_SWEEP_SIGMAS), method="lower"))
    return values
