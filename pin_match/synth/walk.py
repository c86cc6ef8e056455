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

from pin_match.synth.scene import Room

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
    cells = np.argwhere(grid.free)
    if not len(cells):
        raise ValueError("room has no free floor for the camera")
    reach: dict = {}
    for _ in range(20):  # start in a large connected part of the floor
        start = tuple(int(v) for v in cells[rng.integers(len(cells))])
        reach = grid.bfs(start)
        if len(reach) > 0.3 * len(cells):
            break
    reachable = np.array(list(reach))
    pos, yaw = grid.centre(start), float(rng.uniform(-np.pi, np.pi))
    poses: list[tuple[float, float, float]] = []

    def emit() -> bool:
        poses.append((float(pos[0]), float(pos[1]), yaw))
        return len(poses) >= n_frames

    def turn_to(goal_yaw: float) -> bool:
        nonlocal yaw
        while abs(_wrap(goal_yaw - yaw)) > np.radians(5):
            yaw = _wrap(yaw + float(np.clip(_wrap(goal_yaw - yaw), -TURN, TURN)))
            if emit():
                return True
        return False

    def viewpoint(look: tuple[float, float, float]) -> tuple[tuple[int, int], float]:
        x, y, z = look
        near = max(0.7, (CAMERA_HEIGHT - z) / np.tan(np.radians(28)))
        centres = (reachable + 0.5) * CELL
        dist = np.hypot(centres[:, 0] - x, centres[:, 1] - y)
        ok = np.flatnonzero((dist > near) & (dist < max(near + 0.5, MAX_VIEW_DISTANCE)))
        c = reachable[ok[rng.integers(len(ok))]] if len(ok) else reachable[np.argmax(-abs(dist - near))]
        cx, cy = (c + 0.5) * CELL
        return (int(c[0]), int(c[1])), float(np.arctan2(y - cy, x - cx))

    plan: list[tuple[str, int]] = [("look", 0), ("look", 0), ("random", 0), ("random", 0)]
    plan += [("look", k) for k in range(1, min(3, len(looks)))]
    order = [plan[k] for k in rng.permutation(len(plan))]
    if emit():
        return poses
    for _ in range(int(rng.integers(3, 7))):  # look around first, as agents do
        yaw = _wrap(yaw + TURN)
        if emit():
            return poses
    while True:
        for kind, k in order:
            if kind == "look" and looks:
                goal, goal_yaw = viewpoint(looks[k])
            else:
                goal = tuple(int(v) for v in reachable[rng.integers(len(reachable))])
                goal_yaw = float(rng.uniform(-np.pi, np.pi))
            for waypoint in _path(grid, grid.cell(pos), goal)[1:]:
                while np.linalg.norm(waypoint - pos) > 0.05:
                    heading = float(np.arctan2(*(waypoint - pos)[::-1]))
                    if abs(_wrap(heading - yaw)) > np.radians(20):
                        if turn_to(heading):
                            return poses
                        continue
                    pos = pos + (waypoint - pos) * min(1.0, STEP / np.linalg.norm(waypoint - pos))
                    if emit():
                        return poses
            if turn_to(goal_yaw):
                return poses
            if kind == "random" and emit():  # pause: a second look at the same view
                return poses
