"""A robot-like camera walk: PIN's discrete actions (0.25 m forward, 30 degree turns) through free space.

The walk visits a shuffled list of goals: a look-around on the spot, random places in the
room (most frames, which show nothing relevant, as in a real exploration), and viewpoints
0.7-3.5 m from the target and from a same-category distractor, facing them. Paths come
from a breadth-first search on a 10 cm occupancy grid, so the camera never passes through
furniture or walls.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from pin_match.data.synth.scene import Room

CAMERA_HEIGHT = 1.31
STEP = 0.25
TURN = np.radians(30)
CELL = 0.1
CLEARANCE = 0.3
MAX_VIEW_DISTANCE = 3.5


class Grid:
    """Free cells of the room for a camera body of radius ``CLEARANCE``."""

    def __init__(self, room: Room, obstacles: list[tuple[float, float, float, float]]) -> None:
        self.nx, self.ny = int(room.width / CELL), int(room.depth / CELL)
        xs = (np.arange(self.nx) + 0.5) * CELL
        ys = (np.arange(self.ny) + 0.5) * CELL
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        free = (X > CLEARANCE) & (X < room.width - CLEARANCE) & (Y > CLEARANCE) & (Y < room.depth - CLEARANCE)
        for x0, y0, x1, y1 in obstacles:
            free &= ~((X > x0 - CLEARANCE) & (X < x1 + CLEARANCE) & (Y > y0 - CLEARANCE) & (Y < y1 + CLEARANCE))
        self.free = free

    def centre(self, cell: tuple[int, int]) -> np.ndarray:
        return (np.array(cell) + 0.5) * CELL

    def cell(self, xy) -> tuple[int, int]:
        return int(np.clip(xy[0] / CELL, 0, self.nx - 1)), int(np.clip(xy[1] / CELL, 0, self.ny - 1))

    def bfs(self, start: tuple[int, int]) -> dict[tuple[int, int], tuple[int, int] | None]:
        """Parents of every cell reachable from ``start`` (8-connected)."""
        parent: dict[tuple[int, int], tuple[int, int] | None] = {start: None}
        queue = deque([start])
        while queue:
            c = queue.popleft()
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    n = (c[0] + dx, c[1] + dy)
                    if n not in parent and 0 <= n[0] < self.nx and 0 <= n[1] < self.ny and self.free[n]:
                        parent[n] = c
                        queue.append(n)
        return parent

    def line_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        n = int(np.ceil(np.linalg.norm(b - a) / (CELL / 2))) + 1
        return all(self.free[self.cell(a + (b - a) * t)] for t in np.linspace(0, 1, n))


def _path(grid: Grid, start: tuple[int, int], goal: tuple[int, int]) -> list[np.ndarray]:
    """Waypoints from start to goal: the BFS path with corners cut where the straight line is free."""
    parent = grid.bfs(start)
    cells = [goal]
    while parent[cells[-1]] is not None:
        cells.append(parent[cells[-1]])  # type: ignore[arg-type]
    points = [grid.centre(c) for c in reversed(cells)]
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


def camera_walk(room: Room, obstacles: list[tuple[float, float, float, float]],
                looks: list[tuple[float, float, float]], n_frames: int,
                rng: np.random.Generator) -> list[tuple[float, float, float]]:
    """Camera poses (x, y, yaw) for ``n_frames`` frames; ``looks`` are points worth facing (target first)."""
    grid = Grid(room, obstacles)
    start, reachable = _start(grid, rng)
    walk = _Walk(grid, reachable, looks, n_frames, rng, grid.centre(start), float(rng.uniform(-np.pi, np.pi)))
    plan: list[tuple[str, int]] = [("look", 0), ("look", 0), ("random", 0), ("random", 0)]
    plan += [("look", k) for k in range(1, min(3, len(looks)))]
    order = [plan[k] for k in rng.permutation(len(plan))]
    try:
        walk.run(order)
    except _WalkDone:
        pass
    return walk.poses


def _start(grid: Grid, rng: np.random.Generator) -> tuple[tuple[int, int], np.ndarray]:
    """A start cell in a large connected part of the floor, and the cells reachable from it."""
    cells = np.argwhere(grid.free)
    if not len(cells):
        raise ValueError("room has no free floor for the camera")
    reach: dict = {}
    for _ in range(20):
        start = tuple(int(v) for v in cells[rng.integers(len(cells))])
        reach = grid.bfs(start)
        if len(reach) > 0.3 * len(cells):
            break
    return start, np.array(list(reach))


class _WalkDone(Exception):
    """Raised by ``_Walk.emit`` once the walk has all its frames, so every nested loop ends at once."""


class _Walk:
    """An agent-like walk: look around, then visit viewpoints of the looks and random places, in a seeded order."""

    def __init__(self, grid: Grid, reachable: np.ndarray, looks: list[tuple[float, float, float]], n_frames: int,
                 rng: np.random.Generator, pos: np.ndarray, yaw: float) -> None:
        self.grid, self.reachable, self.looks, self.n_frames, self.rng = grid, reachable, looks, n_frames, rng
        self.pos, self.yaw = pos, yaw
        self.poses: list[tuple[float, float, float]] = []

    def emit(self) -> None:
        self.poses.append((float(self.pos[0]), float(self.pos[1]), self.yaw))
        if len(self.poses) >= self.n_frames:
            raise _WalkDone

    def turn_to(self, goal_yaw: float) -> None:
        while abs(_wrap(goal_yaw - self.yaw)) > np.radians(5):
            self.yaw = _wrap(self.yaw + float(np.clip(_wrap(goal_yaw - self.yaw), -TURN, TURN)))
            self.emit()

    def viewpoint(self, look: tuple[float, float, float]) -> tuple[tuple[int, int], float]:
        """A reachable cell that sees ``look`` from a natural distance, and the yaw facing it."""
        x, y, z = look
        near = max(0.7, (CAMERA_HEIGHT - z) / np.tan(np.radians(28)))
        centres = (self.reachable + 0.5) * CELL
        dist = np.hypot(centres[:, 0] - x, centres[:, 1] - y)
        ok = np.flatnonzero((dist > near) & (dist < max(near + 0.5, MAX_VIEW_DISTANCE)))
        c = self.reachable[ok[self.rng.integers(len(ok))]] if len(ok) else \
            self.reachable[np.argmax(-abs(dist - near))]
        cx, cy = (c + 0.5) * CELL
        return (int(c[0]), int(c[1])), float(np.arctan2(y - cy, x - cx))

    def go_to(self, goal: tuple[int, int]) -> None:
        """Walk the grid path in steps, turning first wherever the heading is off by more than 20 degrees."""
        for waypoint in _path(self.grid, self.grid.cell(self.pos), goal)[1:]:
            while np.linalg.norm(waypoint - self.pos) > 0.05:
                heading = float(np.arctan2(*(waypoint - self.pos)[::-1]))
                if abs(_wrap(heading - self.yaw)) > np.radians(20):
                    self.turn_to(heading)
                    continue
                self.pos = self.pos + (waypoint - self.pos) * min(1.0, STEP / np.linalg.norm(waypoint - self.pos))
                self.emit()

    def run(self, order: list[tuple[str, int]]) -> None:
        """Emit poses until ``_WalkDone``."""
        self.emit()
        for _ in range(int(self.rng.integers(3, 7))):  # look around first, as agents do
            self.yaw = _wrap(self.yaw + TURN)
            self.emit()
        while True:
            for kind, k in order:
                if kind == "look" and self.looks:
                    goal, goal_yaw = self.viewpoint(self.looks[k])
                else:
                    goal = tuple(int(v) for v in self.reachable[self.rng.integers(len(self.reachable))])
                    goal_yaw = float(self.rng.uniform(-np.pi, np.pi))
                self.go_to(goal)
                self.turn_to(goal_yaw)
                if kind == "random":  # pause: a second look at the same view
                    self.emit()
