"""The exploration walk blind to the target (``--walk explore``, the default): a tour of the whole house.

An agent that has not found its object yet looks everywhere one could stand. A tour cut off by a
small step budget saw a few pieces of furniture in the start room, and with them only the targets
that happened to stand there; this tour instead looks at every place an object can stand, room by
room, close enough that a small product shows at a few thousand pixels, and ends when it has seen
them all, well within PIN's 1,000-step episodes. It reads the house (rooms, furniture, surfaces,
the floor it can walk) and never which object is the target, so every object's episode in a house
reads the one walk, and a target is met whenever the tour passes it, early or late.

What it looks at: every surface objects stand on (``scene.Surface``), grouped into pieces (a
shelf's boards, a TV stand's two ends), rugs included; objects that fit no surface stand on the
floor along the walls, so each room's walls are swept too. Where it looks from: ``_viewpoints``
covers each piece's surfaces with as few standing spots as it can, each within ``COVER`` of the
points it covers, in front of the piece where it can (a shelf's side panels hide its boards) and
from its sides or farther back where it must (up to ``VIEW_FAR``), so a piece whose front spot is
blocked is still seen and only a piece with no free floor near it is skipped. How it looks: one
heading per 30-degree turn across what the spot covers, at each the 30-degree tilts (PIN's
look-down action) that bring those points into view (``_sweep``). In what order: room by room
from the start, each room's stops in the order of a short walk through them that ends towards
the next room (``_order``), so the tour never doubles back through a doorway.

Every pose differs from the one before by one PIN action: a step of at most 0.25 m, a turn of at
most 30 degrees, or a tilt of 30 degrees.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from pin_match.data.agent import CAMERA_HEIGHT, HALF_HFOV, HALF_VFOV, TILT, TURN
from pin_match.data.synth.scene import Room, Surface
from pin_match.data.synth.walk import (
    CELL,
    TURNED,
    Grid,
    Pose,
    _start,
    _Walk,
    _wrap,
)

VIEW_DISTANCE = 0.6  # metres from a piece's nearest surface point to where the tour prefers to stand: near enough
# that a product on it shows large, far enough that the piece fits a few headings
VIEW_FAR = 1.2  # the farthest a standing spot may be from the piece it looks at
NEAR = 0.5  # the nearest: closer, only a steep look down would show what stands there
COVER = 1.6  # metres from the camera: a point of a piece's surfaces this close to a standing spot is seen large enough
MIN_SHARE = 0.1  # a piece's next standing spot must see this share of its points: a corner left over is seen anyway,
# only from a little farther than ``COVER``
FLOOR_COVER = 3.0  # a floor point this close is seen large enough (what stands on the floor fits no surface: it is
FLOOR_NEAR = 0.75  # large), unless nearer than this (a look 30 degrees down shows the floor from here on) ...
FLOOR_SHARE = 0.3  # ... and a floor's next spot must see this share of it: one look over a room's floor sees most
POINT_SPACING = 0.25  # metres between the points a piece's surfaces are covered by
LOOK_ABOVE = 0.1  # an object's middle stands about this far above its surface: where the tour aims
TILTS = sorted((combo for n in range(1, 5) for combo in combinations((TILT, 0.0, -TILT, -2 * TILT), n)),
               key=lambda combo: (len(combo), sum(map(abs, combo))))  # a heading's tilts: fewest, gentlest first
EDGE = np.radians(5)  # a point aimed at stays this far inside the frame's top and bottom edges ...
SIDE = TURNED + np.radians(3)  # ... and this far inside its sides, where the heading turned to may be off by TURNED
SHELF_AHEAD = 0.15  # a shelf is looked into from in front of it only (metres ahead of its front), its side panels and
# back being solid
WALL_BAND = 0.5  # metres from a wall where objects that fit no surface stand (``placing.FLOOR_BANDS``' first band)


@dataclass(frozen=True)
class _View:
    """A standing spot of the tour and what it does there: per heading (a turn apart), the tilts it looks at."""

    cell: tuple[int, int]
    looks: tuple[tuple[float, tuple[float, ...]], ...]  # (yaw, pitches) per heading


@dataclass(frozen=True)
class _Piece:
    """What one stop or a few of the tour look at: points (x, y, z) where an object's middle could be, the direction
    the piece's front faces (None: a rug or a floor, seen from any side) and its kind: "shelf" (seen from in front
    only), "furniture" (a rug too), or "floor" (a room's floor along its walls, seen from farther: the tour walks
    among its points)."""

    points: np.ndarray
    facing: float | None
    kind: str


def exploration_walk(room: Room, obstacles: list[tuple[float, float, float, float]],
                     away_from: Sequence[tuple[float, float]], n_frames: int, rng: np.random.Generator,
                     ) -> list[Pose]:
    """The tour of the whole house: at most ``n_frames`` poses, fewer when it is done sooner (as it is, within
    PIN's 1,000 steps).

    A look-around where it starts, then every viewpoint of every room (``_viewpoints``), room by room. It
    starts in the room at the end of the house (a house is a row of rooms) farther on average from the points
    ``away_from`` (the house's annotated objects, any of which may be a target), ``START_AWAY`` or more of walk
    from every one of them where the room has such a cell, else at the cell farthest from them (PIN draws a
    start away from its goal): so the targets lie one or two rooms away as often as in PIN's houses. That is
    all it reads of the objects; the tour itself is the same whichever of them is the target.
    """
    grid = Grid(room, obstacles)
    end_room = max((room.rooms[0], room.rooms[-1]), key=lambda r: float(np.mean(
        [np.hypot((r[0] + r[2]) / 2 - x, (r[1] + r[3]) / 2 - y) for x, y in away_from] or [0.0]))) \
        if room.rooms else None
    start, reachable = _start(grid, rng, away_from, weighted=False, within=end_room)
    walk = _Walk(grid, grid, reachable, rng, grid.centre(start), float(rng.uniform(-np.pi, np.pi)), None)
    walk.look_around(int(rng.integers(3, 7)))
    for view in _order(room, grid, start, _viewpoints(room, grid, {tuple(int(v) for v in c) for c in reachable})):
        if len(walk.poses) >= n_frames:
            break
        _look(walk, view)
    return walk.poses[:n_frames]


def _pieces(room: Room) -> list[_Piece]:
    """The places objects stand, as the tour visits them: the surfaces of one piece of furniture together (those
    over its footprint), each rug alone, and per room the floor along its walls: a band ``WALL_BAND`` wide, off
    the furniture and the doorways (where ``placing.place_objects`` stands what fits no surface)."""
    grouped: dict[object, list[Surface]] = {}
    for s in room.surfaces:
        cx, cy = (s.x0 + s.x1) / 2, (s.y0 + s.y1) / 2
        key = next((k for k, (x0, y0, x1, y1) in enumerate(room.footprints) if x0 <= cx <= x1 and y0 <= cy <= y1), s)
        grouped.setdefault(key, []).append(s)
    pieces = [_Piece(np.concatenate([_grid(s.x0, s.y0, s.x1, s.y1, s.z) for s in surfaces]), surfaces[0].facing,
                     "shelf" if surfaces[0].kind == "shelf" else "furniture") for surfaces in grouped.values()]
    b = WALL_BAND / 2
    for x0, y0, x1, y1 in room.rooms or [(0.0, 0.0, room.width, room.depth)]:
        band = np.concatenate([_grid(x0 + b, y0 + b, x1 - b, y0 + b, 0.0), _grid(x0 + b, y1 - b, x1 - b, y1 - b, 0.0),
                               _grid(x0 + b, y0 + b, x0 + b, y1 - b, 0.0), _grid(x1 - b, y0 + b, x1 - b, y1 - b, 0.0)])
        blocked = np.zeros(len(band), bool)
        for bx0, by0, bx1, by1 in [*room.footprints, *room.keep_clear]:
            blocked |= (band[:, 0] > bx0) & (band[:, 0] < bx1) & (band[:, 1] > by0) & (band[:, 1] < by1)
        if not blocked.all():
            pieces.append(_Piece(band[~blocked], None, "floor"))
    return pieces


def _grid(x0: float, y0: float, x1: float, y1: float, z: float) -> np.ndarray:
    """Points (x, y, z) about ``POINT_SPACING`` apart over a rectangle (a line where it is one), at the height an
    object's middle would be over a surface at ``z``."""
    xs = np.linspace(x0, x1, max(1, int(np.ceil((x1 - x0) / POINT_SPACING)) + 1))
    ys = np.linspace(y0, y1, max(1, int(np.ceil((y1 - y0) / POINT_SPACING)) + 1))
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return np.stack([X.ravel(), Y.ravel(), np.full(X.size, z + LOOK_ABOVE)], 1)


def _viewpoints(room: Room, grid: Grid, reachable: set[tuple[int, int]]) -> list[_View]:
    """Standing spots that see every piece's points (``_pieces``) within ``COVER`` (a floor's within
    ``FLOOR_COVER``), a few per piece at most.

    Candidates are the reachable cells of the piece's room within ``VIEW_FAR`` of its points (in front
    of a shelf only; a floor's among its points). Greedily, the candidate that sees most of the points
    still unseen is taken, the one nearest the ideal (``VIEW_DISTANCE`` from the points, in front) among
    those that see as many, until none adds ``MIN_SHARE`` of them: a piece whose front spot is blocked
    is seen from its side or from farther back, and one with no candidate at all is skipped.
    """
    cells = np.array(sorted(reachable))
    centres = (cells + 0.5) * CELL
    room_of = np.array([room.room_of(x, y) for x, y in centres])
    out = []
    for piece in _pieces(room):
        points = piece.points
        inside = room_of == room.room_of(*points[:, :2].mean(0))
        far = np.hypot(centres[inside, None, 0] - points[None, :, 0], centres[inside, None, 1] - points[None, :, 1])
        floor = piece.kind == "floor"
        near, cover, share = (FLOOR_NEAR, FLOOR_COVER, FLOOR_SHARE) if floor else (NEAR, COVER, MIN_SHARE)
        gap = far.min(1)
        ok = floor | ((gap >= NEAR) & (gap <= VIEW_FAR))
        cost = np.abs(gap - VIEW_DISTANCE)
        if piece.facing is not None:
            front = np.array([np.cos(piece.facing), np.sin(piece.facing)])
            offset = centres[inside] - points[:, :2].mean(0)
            cost = cost + 0.5 * (1.0 - (offset @ front) / np.maximum(np.hypot(*offset.T), 1e-6))
            if piece.kind == "shelf":
                depth = float(np.ptp(points[:, :2] @ front))
                width = float(np.ptp(points[:, :2] @ np.array([-front[1], front[0]])))
                ahead = offset @ front - depth / 2
                ok &= (ahead >= SHELF_AHEAD) & (np.abs(offset @ np.array([-front[1], front[0]])) - width / 2 <= ahead)
        sees = (far[ok] >= near) & (np.hypot(far[ok], CAMERA_HEIGHT - points[None, :, 2]) <= cover)
        candidates, cost = cells[inside][ok], cost[ok]
        unseen = np.ones(len(points), bool)
        while len(candidates):
            gain = (sees & unseen).sum(1)
            if gain.max() < max(1.0, share * len(points)):
                break
            k = int(np.argmin(np.where(gain == gain.max(), cost, np.inf)))
            at = (candidates[k] + 0.5) * CELL
            out.append(_View(tuple(int(v) for v in candidates[k]), _sweep(at, points[sees[k] & unseen])))
            unseen &= ~sees[k]
    return out


def _sweep(at: np.ndarray, points: np.ndarray) -> tuple[tuple[float, tuple[float, ...]], ...]:
    """Headings from ``at`` that bring every point into the 42 degree wide view, a turn apart (just one where the
    points fit it; none where no point falls in it), each with the fewest and gentlest tilts, multiples of PIN's 30
    degrees, that bring the points it faces into the view's height (``EDGE`` inside its edges)."""
    bearing = np.arctan2(points[:, 1] - at[1], points[:, 0] - at[0])
    mid = float(np.arctan2(np.sin(bearing).mean(), np.cos(bearing).mean()))
    rel = (bearing - mid + np.pi) % (2 * np.pi) - np.pi
    lo, hi = float(rel.min()), float(rel.max())
    turns = int(np.ceil(max(hi - lo - 2 * (HALF_HFOV - SIDE), 0.0) / TURN))
    elevation = np.arctan2(points[:, 2] - CAMERA_HEIGHT, np.hypot(points[:, 0] - at[0], points[:, 1] - at[1]))
    reach = HALF_VFOV - EDGE
    out = []
    for k in range(turns + 1):
        yaw = (lo + hi) / 2 + (k - turns / 2) * TURN
        faced = elevation[np.abs(rel - yaw) <= HALF_HFOV]
        if len(faced):
            out.append((_wrap(mid + yaw), next(tilts for tilts in TILTS
                                               if all(any(abs(e - p) <= reach for p in tilts) for e in faced))))
    return tuple(out)


def _order(room: Room, grid: Grid, start: tuple[int, int], views: list[_View]) -> list[_View]:
    """The views room by room, the start's room first, then the others by their walk from the start; in each room
    the stops in the order of a short walk from where the tour enters it through all of them to the room it goes
    to next (``_shortest``)."""
    rooms: dict[int, list[_View]] = {}
    for view in views:
        rooms.setdefault(room.room_of(*grid.centre(view.cell)), []).append(view)
    lengths = {view.cell: grid.path_lengths(view.cell) for view in views}
    from_start = grid.path_lengths(start)
    cells = np.argwhere(grid.free)
    room_of = np.array([room.room_of(*grid.centre(c)) for c in cells])

    def to_room(dist: np.ndarray, r: int) -> float:
        return float(dist[cells[room_of == r, 0], cells[room_of == r, 1]].min())

    sequence = sorted(rooms, key=lambda r: to_room(from_start, r))
    out: list[_View] = []
    here = start
    for n, r in enumerate(sequence):
        stops = rooms[r]
        cost = np.array([[lengths[a.cell][b.cell] for b in stops] for a in stops])
        first = np.array([lengths[v.cell][here] for v in stops])
        last = np.array([to_room(lengths[v.cell], sequence[n + 1]) for v in stops]) if n + 1 < len(sequence) \
            else np.zeros(len(stops))
        route = _shortest(cost, first, last)
        out += [stops[k] for k in route]
        here = stops[route[-1]].cell
    return out


def _shortest(cost: np.ndarray, first: np.ndarray, last: np.ndarray) -> list[int]:
    """An open route through every stop: ``first`` the walk to each from where it starts, ``cost`` between two,
    ``last`` from each on to where it goes next; nearest first, then 2-opt (reverse a stretch while it shortens)."""
    left = list(range(len(first)))
    route = [left.pop(int(np.argmin(first)))]
    while left:
        route.append(left.pop(int(np.argmin([cost[route[-1], k] for k in left]))))

    def length(r: list[int]) -> float:
        return float(first[r[0]] + sum(cost[a, b] for a, b in zip(r, r[1:])) + last[r[-1]])

    better = True
    while better:
        better = False
        for i in range(len(route) - 1):
            for j in range(i + 2, len(route) + 1):
                candidate = route[:i] + route[i:j][::-1] + route[j:]
                if length(candidate) < length(route) - 1e-9:
                    route, better = candidate, True
    return route


def _look(walk: _Walk, view: _View) -> None:
    """Walk to a view (level, as every view leaves the camera) and look as it says, one PIN action a pose: per heading
    (the nearest end of the sweep first) a turn and the tilts, one 30 degree step a pose, then level again."""
    walk.go_to(view.cell)
    looks = view.looks
    if abs(_wrap(looks[-1][0] - walk.yaw)) < abs(_wrap(looks[0][0] - walk.yaw)):
        looks = looks[::-1]
    for yaw, pitches in looks:
        walk.turn_to(yaw)
        if abs(pitches[-1] - walk.pitch) < abs(pitches[0] - walk.pitch):
            pitches = pitches[::-1]
        for pitch in pitches:
            _tilt(walk, pitch)
    _tilt(walk, 0.0)


def _tilt(walk: _Walk, pitch: float) -> None:
    """Tilt to ``pitch`` in steps of PIN's 30 degrees, a pose each."""
    while abs(pitch - walk.pitch) > 1e-9:
        walk.pitch = walk.pitch + float(np.clip(pitch - walk.pitch, -TILT, TILT))
        walk.emit()
