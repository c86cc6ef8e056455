"""A PIN agent's camera walks, with PIN's discrete actions (0.25 m forward, turns of at most 30 degrees) along
shortest paths (``paths.GridWalks``, the engine of every distance) on a 10 cm occupancy grid (never through
furniture or walls): the grid, the walker (``_Walk``) and the helpers every walk shares.

The default walk, the exploration that does not know the target, is a tour of the whole house
(``tour.exploration_walk``): every episode of a house reads that one walk.

The walk that heads for the target, ``camera_walk`` (``--walk seek``), is a successful agent's
walk: the target is seen far, then near, and the episode ends within about 1 m of it, facing it,
after a pass by a same-category look-alike. It knows the answer, so it serves first-match studies:

1. a look-around on the spot;
2. exploration: random places, until the frames the two runs at an object need are all that is left
   of the episode (most of these frames show nothing relevant, as in a real exploration);
3. a pass by a same-category look-alike: a straight run at it, facing it, drawn as the
   target's (the same run to the same kind of stop spot, without the stop);
4. the run at the target: from 1-1.75 m further out, straight at the target, one frame per step,
   to a stop distance at which the target fills a few thousand pixels (at most 1 m), then
   the stop: the camera tilts down or up in two steps to centre the target (as an agent's
   look-down action) and the episode ends there.

The camera has no pitch except in the runs (steps 3 and 4), where an object below
the field of view is brought into it by tilting, as a robot's head would.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from pin_match.data.agent import CAMERA_HEIGHT, FOCAL_PX, FORWARD_STEP, HALF_VFOV, TURN
from pin_match.data.geometry import AGENT_RADIUS, FloorMap
from pin_match.data.paths import GridWalks
from pin_match.data.synth.scene import Room

CELL = 0.1
MAP_CELL = 0.05  # the stored floor map's cell: finer than the walk's, since a stop beside furniture is measured on it
START_AWAY = 2.0  # metres of walk at least from the start to the target: PIN's 1 m success distance and as much again
CLEARANCE = 0.3  # the camera body's radius while exploring
NEAR_CLEARANCE = 0.1  # how close to furniture the camera may stand when it stops beside an object
STOP_PIXELS = 12000.0  # the stop distance shows the object at about this many pixels ...
MAX_STOP = 1.0  # ... but never further than this on the floor (PIN's success radius)
MIN_STOP = 0.45  # the closest a stop may be (3D distance from the camera to the object's centre) ...
MIN_STAND = 0.25  # ... and the camera never stands over the object (horizontal distance)
SECTOR = np.radians(30)  # stop spots are compared one per sector of this angle around the object
RUN = (1.0, 1.75)  # the straight run at an object starts this far (metres) behind its stop: the target and a
# look-alike passed on the way alike, so neither is met larger by construction
TURNED = np.radians(5)  # ``turn_to`` stops turning once the heading is this near the one it turns to
RUN_FRAMES = 40  # about what the two runs at an object take, walking there included; exploration gets the rest


@dataclass(frozen=True)
class Goal:
    """An object a walk runs at: its centre (metres) and the area it shows seen from the side (m^2)."""

    x: float
    y: float
    z: float
    area: float

    def stop_distance(self) -> float:
        """How far from the object's centre an agent would stop to see it large (at most 1 m)."""
        return float(np.clip(FOCAL_PX * np.sqrt(self.area / STOP_PIXELS), MIN_STOP, MAX_STOP))


Pose = tuple[float, float, float, float]  # x, y, yaw, pitch (radians)


def standable(room: Room, obstacles: list[tuple[float, float, float, float]], clearance: float,
              cell: float) -> np.ndarray:
    """Cells of ``cell`` metres ([i, j]: x, y) whose centre is at least ``clearance`` from the walls and from every
    obstacle rectangle (x0, y0, x1, y1): where a body of that radius fits."""
    xs = (np.arange(int(room.width / cell)) + 0.5) * cell
    ys = (np.arange(int(room.depth / cell)) + 0.5) * cell
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    free = (X > clearance) & (X < room.width - clearance) & (Y > clearance) & (Y < room.depth - clearance)
    for x0, y0, x1, y1 in obstacles:
        free &= ~((X > x0 - clearance) & (X < x1 + clearance) & (Y > y0 - clearance) & (Y < y1 + clearance))
    return free


def floor_map(room: Room, obstacles: list[tuple[float, float, float, float]]) -> FloorMap:
    """Where PIN's agent (its radius) can stand in the room, at ``MAP_CELL``: what the navigation estimate reads."""
    return FloorMap(standable(room, obstacles, AGENT_RADIUS, MAP_CELL), MAP_CELL)


class Grid:
    """Free cells of the room for a camera body of radius ``clearance``."""

    def __init__(self, room: Room, obstacles: list[tuple[float, float, float, float]],
                 clearance: float = CLEARANCE) -> None:
        self.free = standable(room, obstacles, clearance, CELL)
        self.nx, self.ny = self.free.shape
        self.walks = GridWalks(self.free, CELL)

    def centre(self, cell: tuple[int, int]) -> np.ndarray:
        return (np.array(cell) + 0.5) * CELL

    def cell(self, xy) -> tuple[int, int]:
        return int(np.clip(xy[0] / CELL, 0, self.nx - 1)), int(np.clip(xy[1] / CELL, 0, self.ny - 1))

    def path_lengths(self, start: tuple[int, int]) -> np.ndarray:
        """Shortest 8-connected walk (metres, a diagonal step sqrt(2) cells) from ``start`` to every cell; inf where
        unreachable (the one path engine, ``paths.GridWalks``)."""
        return self.walks.on_grid(self.walks.from_node(int(self.walks.node[start]))[0])

    def lengths_to(self, xy: tuple[float, float], reach: float = 1.5) -> np.ndarray:
        """The walk from every cell to a point that may stand off the floor (on furniture): the straight stretch
        from a free cell within ``reach`` of it, then the shortest walk; inf where no such cell is reachable."""
        straight = np.hypot(*((self.walks.cells + 0.5) * CELL - np.asarray(xy)).T)
        near = np.flatnonzero(straight <= reach)
        return self.walks.on_grid(self.walks.from_nodes(near, straight[near]))

    def main_floor(self) -> np.ndarray:
        """The cells (i, j) of the largest connected part of the free floor, sorted."""
        return self.walks.cells[self.walks.largest_part()]

    def line_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        n = int(np.ceil(np.linalg.norm(b - a) / (CELL / 2))) + 1
        return all(self.free[self.cell(a + (b - a) * t)] for t in np.linspace(0, 1, n))


def _path(grid: Grid, start: tuple[int, int], goal: tuple[int, int]) -> list[np.ndarray]:
    """Waypoints from start to goal: the shortest walk on the grid with corners cut where the straight line is free.

    A goal the walker cannot reach from ``start`` (or a cell that is not free) gives no path (the walker stays).
    """
    source, target = int(grid.walks.node[start]), int(grid.walks.node[goal])
    cells = grid.walks.path(source, target) if source >= 0 and target >= 0 else []
    if not cells:
        return [grid.centre(start)]
    points = [grid.centre(tuple(grid.walks.cells[c])) for c in cells]
    out = [points[0]]
    k = 0
    while k < len(points) - 1:
        j = len(points) - 1
        while j > k + 1 and not grid.line_free(points[k], points[j]):
            j -= 1
        out.append(points[j])
        k = j
    return out


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


Sight = Callable[[Goal, Pose], float]  # how many pixels of the object a pose shows (a quick render)


def camera_walk(room: Room, obstacles: list[tuple[float, float, float, float]], target: Goal,
                lookalikes: list[Goal], n_frames: int, rng: np.random.Generator, sight: Sight | None = None,
                ) -> list[Pose]:
    """The walk that heads for the target (``--walk seek``): explore, pass one look-alike, run at ``target``
    and stop beside it. It knows the answer, so it serves first-match studies only.

    About ``n_frames`` poses: exploration takes what the runs leave of it (at least a
    look-around), and the runs always go to the end, so a short ``n_frames`` gives a
    longer episode rather than one that never nears its target. ``sight`` lets the walk choose,
    among stop spots at about the right distance, the one from which the object shows most (a
    shelf's side panel or a sofa back hides what a floor plan cannot tell); without it the
    spot nearest the stop distance is taken.
    """
    grid = Grid(room, obstacles)
    near = Grid(room, obstacles, NEAR_CLEARANCE)
    start, reachable = _start(grid, rng, [(target.x, target.y)])
    walk = _Walk(grid, near, reachable, rng, grid.centre(start), float(rng.uniform(-np.pi, np.pi)), sight)
    walk.look_around(int(rng.integers(3, 7)))
    walk.explore(n_frames - RUN_FRAMES)
    if lookalikes:
        walk.run_at(lookalikes[int(rng.integers(len(lookalikes)))], RUN, stop=False)
    walk.run_at(target, RUN, stop=True)
    return walk.poses


def _start(grid: Grid, rng: np.random.Generator, targets: Sequence[tuple[float, float]],
           weighted: bool = True, within: tuple[float, float, float, float] | None = None,
           ) -> tuple[tuple[int, int], np.ndarray]:
    """A start cell on the main floor (the largest connected part: a corner that furniture and floor objects wall off
    would keep the walk in it), inside the rectangle ``within`` where that holds cells, and the main floor's cells.

    Never within reach of a target: a start cell lies ``START_AWAY`` or more of walk from each of
    ``targets`` (straight distance where a target's cell reaches no free cell), drawn uniformly or, where
    ``weighted``, with weight its distance to the nearest, so the farther corners of the room, where PIN's
    long episodes would start, come first. A room too small for that starts at its farthest cell.
    """
    if not grid.free.any():
        raise ValueError("room has no free floor for the camera")
    cells = main = grid.main_floor()
    if within is not None:
        x0, y0, x1, y1 = within
        centres = (cells + 0.5) * CELL
        inside = (centres[:, 0] > x0) & (centres[:, 0] < x1) & (centres[:, 1] > y0) & (centres[:, 1] < y1)
        cells = cells[inside] if inside.any() else cells
    away = np.full(len(cells), np.inf)
    for target in targets:
        walked = grid.lengths_to(target)[cells[:, 0], cells[:, 1]]
        away = np.minimum(away, np.where(np.isfinite(walked), walked,
                                         np.hypot(*((cells + 0.5) * CELL - np.asarray(target)).T)))
    far = np.flatnonzero(away >= START_AWAY)
    weights = away[far] / away[far].sum() if len(far) and weighted else None
    k = int(rng.choice(far, p=weights)) if len(far) else int(np.argmax(away))
    return (int(cells[k][0]), int(cells[k][1])), main


def _pitch_for(eye: np.ndarray, look: Goal, centre: bool) -> float:
    """The camera's tilt: none while ``look`` is well inside the view, else just enough (or, to centre it, all)."""
    elevation = float(np.arctan2(look.z - CAMERA_HEIGHT, np.hypot(look.x - eye[0], look.y - eye[1])))
    if centre:
        return elevation
    margin = HALF_VFOV - np.radians(12)
    return float(np.clip(0.0, elevation - margin, elevation + margin))


class _Walk:
    """The agent's state (position, heading) and the poses it has emitted."""

    def __init__(self, grid: Grid, near: Grid, reachable: np.ndarray, rng: np.random.Generator, pos: np.ndarray,
                 yaw: float, sight: Sight | None) -> None:
        self.grid, self.near, self.reachable, self.rng, self.sight = grid, near, reachable, rng, sight
        self.pos, self.yaw, self.pitch = pos, yaw, 0.0
        self.poses: list[Pose] = []
        self.emit()

    def emit(self) -> None:
        self.poses.append((float(self.pos[0]), float(self.pos[1]), self.yaw, self.pitch))

    def look_around(self, turns: int) -> None:
        for _ in range(turns):
            self.yaw = _wrap(self.yaw + TURN)
            self.emit()

    def turn_to(self, goal_yaw: float) -> None:
        while abs(_wrap(goal_yaw - self.yaw)) > TURNED:
            self.yaw = _wrap(self.yaw + float(np.clip(_wrap(goal_yaw - self.yaw), -TURN, TURN)))
            self.emit()

    def go_to(self, goal: tuple[int, int], budget: int | None = None) -> None:
        """Walk the grid path in steps, turning first wherever the heading is off by more than 20 degrees.

        With ``budget``, stop once the walk holds that many poses.
        """
        self.pitch = 0.0
        for waypoint in _path(self.grid, self.grid.cell(self.pos), goal)[1:]:
            while np.linalg.norm(waypoint - self.pos) > 0.05:
                if budget is not None and len(self.poses) >= budget:
                    return
                heading = float(np.arctan2(*(waypoint - self.pos)[::-1]))
                if abs(_wrap(heading - self.yaw)) > np.radians(20):
                    self.turn_to(heading)
                    continue
                ahead = float(np.linalg.norm(waypoint - self.pos))
                self.pos = self.pos + (waypoint - self.pos) * min(1.0, FORWARD_STEP / ahead)
                self.emit()

    def explore(self, budget: int) -> None:
        """Random places (with a pause and a look at each), until the walk holds ``budget`` poses."""
        while len(self.poses) < budget:
            goal = tuple(int(v) for v in self.reachable[self.rng.integers(len(self.reachable))])
            self.go_to(goal, budget)
            if len(self.poses) < budget:
                self.turn_to(float(self.rng.uniform(-np.pi, np.pi)))

    def run_at(self, look: Goal, run: tuple[float, float], stop: bool) -> None:
        """Walk to a spot ``run`` metres further out than the stop, then straight at ``look``, facing it each step."""
        final = self._stop_spot(look)
        first = self._run_start(look, final, run)
        if not self.near.line_free(first, final):
            final = first
        self.go_to(self.grid.cell(first))
        self.pos = first if np.linalg.norm(first - self.pos) < 0.1 else self.pos
        goal = np.array([look.x, look.y])
        self.turn_to(float(np.arctan2(*(goal - self.pos)[::-1])))
        while True:
            self.yaw = float(np.arctan2(*(goal - self.pos)[::-1]))
            self.pitch = _pitch_for(self.pos, look, centre=False)
            self.emit()
            left = float(np.linalg.norm(final - self.pos))
            if left < 0.05:
                break
            self.pos = self.pos + (final - self.pos) * min(1.0, FORWARD_STEP / left)
        if stop:  # the agent looks at what it found, tilting in two steps, then stops
            centre = _pitch_for(self.pos, look, centre=True)
            for pitch in ((self.pitch + centre) / 2, centre):
                self.pitch = pitch
                self.emit()
        self.pitch = 0.0

    def _stop_spot(self, look: Goal) -> np.ndarray:
        """A free spot (close to furniture allowed) near the stop distance from which the object shows well.

        Candidates: per 30 degree sector around the object, the spot nearest the stop distance;
        with ``sight``, the one showing most of the object wins, else the nearest to the distance.
        """
        cells = np.argwhere(self.near.free)
        centres = (cells + 0.5) * CELL
        horizontal = np.hypot(centres[:, 0] - look.x, centres[:, 1] - look.y)
        distance = np.hypot(horizontal, CAMERA_HEIGHT - look.z)
        cost = np.abs(distance - look.stop_distance()) + 2.0 * ((horizontal > MAX_STOP) | (horizontal < MIN_STAND))
        cost = cost + 1e-3 * self.rng.random(len(cost))
        sector = np.floor((np.arctan2(centres[:, 1] - look.y, centres[:, 0] - look.x) + np.pi) / SECTOR).astype(int)
        best = [int(np.flatnonzero(sector == k)[np.argmin(cost[sector == k])]) for k in np.unique(sector)]
        best = sorted(best, key=lambda k: cost[k])
        if self.sight is None:
            return centres[best[0]]
        shows = [self.sight(look, self._facing(centres[k], look)) if cost[k] < 1.0 else 0.0 for k in best]
        return centres[best[int(np.argmax(shows))]]  # the first (nearest the distance) among equals

    @staticmethod
    def _facing(at: np.ndarray, look: Goal) -> Pose:
        yaw = float(np.arctan2(look.y - at[1], look.x - at[0]))
        return float(at[0]), float(at[1]), yaw, _pitch_for(at, look, centre=True)

    def _run_start(self, look: Goal, final: np.ndarray, run: tuple[float, float]) -> np.ndarray:
        """A reachable spot ``run`` metres behind ``final`` (seen from the object), with a straight free line to it."""
        centres = (self.reachable + 0.5) * CELL
        away = final - np.array([look.x, look.y])
        away = away / max(float(np.linalg.norm(away)), 1e-6)
        offset = centres - final
        along = offset @ away
        side = np.abs(offset @ np.array([-away[1], away[0]]))
        ok = np.flatnonzero((along > run[0]) & (along < run[1]) & (side < 0.6 * along))
        behind = ok[np.argsort(side[ok] / along[ok] + 0.05 * self.rng.random(len(ok)))]
        nearest = np.argsort(np.linalg.norm(offset, axis=1))  # no room behind: the nearest spot in sight
        for k in [*behind[:40], *nearest[:200]]:
            if self.near.line_free(centres[k], final):
                return centres[k]
        return centres[nearest[0]]  # nothing in sight of the stop: stop at the nearest reachable spot instead
