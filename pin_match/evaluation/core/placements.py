"""Where a scored frame's matched points are in the house, and what an agent walking up to them would meet.

The navigation estimate (``navigation``) follows a walk until a stop policy fires on a frame whose matched points
can be placed: back-projected with the frame's depth, pose and camera, their median is the goal point. An
approach-verify policy then walks up to the goal point (``data.walkup``) and looks again; its views are a synthetic
set's walk-ups, rendered and scored on demand (``WalkUpViews``), or a PIN recording's recorded approach views. A
rejected goal point is remembered by the cells of the agent's own map around it, never by what it turned out to be.
``Placements`` places each frame's points once and serves every sigma.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.data.geometry import Geometry
from pin_match.data.walkup import WalkUp, remembered_cells, walk_up
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.metrics import FrameArrays
from pin_match.evaluation.core.stop import CloseLook

DEPTH_RANGE = (0.5, 5.0)  # PIN's depth sensor, metres: below the first or at the second a pixel has no depth
RECORDED_ON = 0.5  # metres: a recording's approach views are of the object whose centre is this near the goal point


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
                 approach: pd.DataFrame | None = None, walkups: WalkUpViews | None = None) -> None:
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
        self.recorded_views = _approach_views(fs, approach)  # a recording's approach views
        self.walkups = walkups
        self._walk_up_of: dict[tuple[int, bytes], WalkUp] = {}
        self.walks: dict[tuple[int, bytes], tuple[np.ndarray, float, int]] = {}  # ``_walk_to``'s, by frame and point

    def close_look(self, frame: int, placed: tuple[np.ndarray, str], within: float) -> CloseLook:
        """Frame ``frame``'s candidate, placed at ``placed``'s goal point, as an agent walking up to it meets it,
        remembered by the cells of its map around the goal point (``walkup.remembered_cells``). A synthetic set's views
        are the walk-up's (``WalkUp.needed`` of ``within``), scored on demand (None until they are); a recording's
        are the approach views it recorded of the object whose centre is within ``RECORDED_ON`` of the goal (the
        recording says which object its agent walked up to); without either, none."""
        goal = placed[0]
        key, around = remembered_cells(goal)
        episode_id = str(self.arrays.episode_ids[self.arrays.episode[frame]])
        if self.walkups is not None:
            walkup = self.walk_up(frame, goal)
            views = () if walkup is None else self.walkups.views(episode_id, walkup, within)
            return CloseLook(key, views, around)
        positions = self.geometry.episodes[episode_id].positions
        if positions and self.recorded_views:
            ids = list(positions)
            gaps = np.linalg.norm(np.asarray([positions[i] for i in ids], np.float64) - goal, axis=1)
            nearest = int(np.argmin(gaps))
            if gaps[nearest] <= RECORDED_ON:
                return CloseLook(key, self.recorded_views.get((episode_id, ids[nearest]), ()), around)
        return CloseLook(key, (), around)

    def walk_up(self, frame: int, goal: np.ndarray) -> WalkUp | None:
        """The walk-up from frame ``frame``'s pose to the goal point on its episode's floor map (None without one)."""
        episode_id = str(self.arrays.episode_ids[self.arrays.episode[frame]])
        floor = self.geometry.episodes[episode_id].floor_map
        if floor is None:
            return None
        key = (frame, np.asarray(goal, np.float64).tobytes())
        if key not in self._walk_up_of:
            self._walk_up_of[key] = walk_up(floor, *self.xy[frame], float(self.yaw[frame]), goal)
        return self._walk_up_of[key]

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


class WalkUpViews(Protocol):
    """Where an approach-verify policy's walk-up views come from (``scoring.walkups.RenderedWalkUps``): their
    scores, None while not scored, and a call that renders and scores what was asked for."""

    def views(self, episode_id: str, walkup: WalkUp, within: float) -> tuple[tuple[float, float], ...] | None: ...

    def resolve(self) -> bool: ...


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
