"""The walk-up: what an agent does, with PIN's actions, when it leaves its route to check a candidate.

The agent knows where it stands (its pose when the candidate fired), the goal point (the matched points
back-projected with the frame's depth) and its own floor map; nothing else. It walks the map's shortest path
to where it can stand beside the goal (``FloorMap.stand``): before each 0.25 m forward step it turns in
30-degree steps until the path ahead is within half a turn of its heading (its heading stays a multiple of 30
degrees from where it started, as PIN's turns leave it); at the standing point it turns to face the goal and
looks down (or up) in 30-degree steps until the goal is within half a tilt of the view's centre. Every action
gives a view, and each view's distance to the goal point is what the agent measures from its map.

Going back after a rejection costs the tilts back to level, an about-turn, the same forward steps and the
turns to its old heading (``WalkUp.back``); the agent does not look while it walks back.

One simplification, stated: a forward step moves the agent 0.25 m along the path (the last one what is left of
it), not 0.25 m along its quantised heading with the simulator's sliding along walls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pin_match.data.agent import CAMERA_HEIGHT, FORWARD_STEP, TILT, TURN
from pin_match.data.geometry import FloorMap

Pose = tuple[float, float, float, float]  # x, y, yaw, pitch (radians): a view as the renderer takes it
MAX_TILT = 2  # looks down at most 60 degrees, up at most 60 (PIN's tilt actions)
REMEMBERED_CELL = 0.25  # metres: the cells of the agent's map a rejected goal point is remembered by ...
REMEMBERED_AROUND = 0.5  # ... every cell whose centre is within this of the goal point


@dataclass(frozen=True)
class WalkUp:
    """The views of a walk-up, one per action (turn, forward step, tilt) in the order taken, and each view's
    horizontal distance to the goal point; the metres walked, and the actions the walk back to the route costs."""

    poses: tuple[Pose, ...]
    distances: tuple[float, ...]
    walked: float
    back: int
    end: tuple[float, float]  # where it stands at the end (x, y)

    @property
    def actions(self) -> int:
        """Actions from leaving the route to standing beside the goal, looking at it."""
        return len(self.poses)

    def needed(self, within: float) -> list[int]:
        """The views an approach-verify policy with distance ``within`` reads: those within it, else those nearest
        the goal (where it got no closer)."""
        if not self.poses:
            return []
        near = [k for k, d in enumerate(self.distances) if d <= within]
        if near:
            return near
        closest = min(self.distances)
        return [k for k, d in enumerate(self.distances) if d <= closest + 1e-9]


def remembered_cells(goal: np.ndarray) -> tuple[tuple[int, int], frozenset]:
    """What an agent remembers of a goal point it walked up to and rejected: the cell of its map
    (``REMEMBERED_CELL``) the point falls in, and every cell whose centre is within ``REMEMBERED_AROUND`` of it (a
    later candidate whose goal falls in one of them is the same thing, seen again)."""
    cell = np.floor(np.asarray(goal[:2], np.float64) / REMEMBERED_CELL).astype(int)
    reach = int(np.ceil(REMEMBERED_AROUND / REMEMBERED_CELL))
    around = set()
    for di in range(-reach, reach + 1):
        for dj in range(-reach, reach + 1):
            centre = (cell + (di, dj) + 0.5) * REMEMBERED_CELL
            if np.hypot(*(centre - goal[:2])) <= REMEMBERED_AROUND:
                around.add((int(cell[0] + di), int(cell[1] + dj)))
    return (int(cell[0]), int(cell[1])), frozenset(around | {(int(cell[0]), int(cell[1]))})


def pose_key(pose: Pose) -> str:
    """A view's name: its position to the millimetre, its yaw and pitch to the tenth of a milliradian."""
    x, y, yaw, pitch = pose
    return f"{x:.3f}_{y:.3f}_{_wrap(yaw):.4f}_{pitch:.4f}".replace("-0.000", "0.000")


def walk_up(floor: FloorMap, x: float, y: float, yaw: float, goal: np.ndarray) -> WalkUp:
    """The walk-up from (x, y), heading ``yaw`` (pitch level), to beside ``goal`` (x, y, z)."""
    start = np.array([x, y], np.float64)
    goal = np.asarray(goal, np.float64)
    stand = floor.stand(goal[:2], start)
    route = _straighten(floor, floor.path(start, stand))
    lengths = np.r_[0.0, np.cumsum(np.hypot(*np.diff(route, axis=0).T))]
    poses: list[Pose] = []
    heading, pos, along = float(yaw), start, 0.0
    legs: list[float] = []  # the direction of each forward step
    middle_turns = 0  # turns between the first and the last forward step: the walk back makes as many
    while lengths[-1] - along > 1e-6:
        along_next = min(along + FORWARD_STEP, float(lengths[-1]))
        ahead = _point(route, lengths, along_next)
        legs.append(math.atan2(ahead[1] - pos[1], ahead[0] - pos[0]))
        before = len(poses)
        heading = _turn_to(poses, pos, heading, legs[-1])
        middle_turns += (len(poses) - before) if len(legs) > 1 else 0
        pos, along = ahead, along_next
        poses.append((float(pos[0]), float(pos[1]), heading, 0.0))
    horizontal = float(np.hypot(*(goal[:2] - pos)))
    if horizontal > 1e-6:
        heading = _turn_to(poses, pos, heading, math.atan2(goal[1] - pos[1], goal[0] - pos[0]))
    elevation = math.atan2(goal[2] - CAMERA_HEIGHT, horizontal)
    tilts = int(np.clip(round(elevation / TILT), -MAX_TILT, MAX_TILT))
    for k in range(1, abs(tilts) + 1):
        poses.append((float(pos[0]), float(pos[1]), heading, math.copysign(k * TILT, tilts)))
    distances = tuple(float(np.hypot(goal[0] - p[0], goal[1] - p[1])) for p in poses)
    if legs:  # level again, about-turn onto the path, walk it back, turn to the old heading
        back = abs(tilts) + _turns(heading, legs[-1] + math.pi) + len(legs) + middle_turns + \
            _turns(legs[0] + math.pi, yaw)
    else:  # it never moved: level again and turn back
        back = abs(tilts) + _turns(heading, yaw)
    return WalkUp(tuple(poses), distances, float(lengths[-1]), back, (float(pos[0]), float(pos[1])))


def _straighten(floor: FloorMap, route: np.ndarray) -> np.ndarray:
    """The route with its corners cut wherever the straight line stays on standable cells: the map's 8-connected
    cells make a staircase of a diagonal, which an agent walks straight."""
    out, k = [route[0]], 0
    while k < len(route) - 1:
        j = len(route) - 1
        while j > k + 1 and not _clear(floor, route[k], route[j]):
            j -= 1
        out.append(route[j])
        k = j
    return np.array(out)


def _clear(floor: FloorMap, a: np.ndarray, b: np.ndarray) -> bool:
    """Is every point of the segment a-b (its ends apart) on a standable cell?"""
    n = int(np.ceil(np.hypot(*(b - a)) / (floor.cell / 2))) + 1
    points = a + (b - a) * np.linspace(0.0, 1.0, n)[1:-1, None]
    cells = np.floor((points - np.asarray(floor.origin)) / floor.cell).astype(int)
    inside = (cells >= 0).all(axis=1) & (cells[:, 0] < floor.free.shape[0]) & (cells[:, 1] < floor.free.shape[1])
    return bool(inside.all() and floor.free[cells[:, 0], cells[:, 1]].all())


def _turn_to(poses: list[Pose], pos: np.ndarray, heading: float, direction: float) -> float:
    """Turn in 30-degree steps (each a view) until ``direction`` is within half a turn of the heading."""
    while abs(_wrap(direction - heading)) > TURN / 2 + 1e-9:
        heading = _wrap(heading + math.copysign(TURN, _wrap(direction - heading)))
        poses.append((float(pos[0]), float(pos[1]), heading, 0.0))
    return heading


def _turns(heading: float, direction: float) -> int:
    """Turn actions from ``heading`` until ``direction`` is within half a turn."""
    return max(0, math.ceil((abs(_wrap(direction - heading)) - TURN / 2) / TURN - 1e-9))


def _point(route: np.ndarray, lengths: np.ndarray, along: float) -> np.ndarray:
    return np.array([np.interp(along, lengths, route[:, 0]), np.interp(along, lengths, route[:, 1])])


def _wrap(angle: float) -> float:
    return float((angle + math.pi) % (2 * math.pi) - math.pi)
