"""Furnished rooms and where objects go: floor, walls, ceiling, furniture with support surfaces.

A room is a pure function of its scene seed, so every episode of one scene sees the same
room; object placement is drawn from the episode's own generator. Furniture is axis-aligned
and kept away from the room's middle so the camera walk always has space.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pin_match.data.synth import textures as tx
from pin_match.data.synth.shapes import Mesh, box, cylinder, ellipsoid, merge

WALL_HEIGHT = 2.6


@dataclass(frozen=True)
class Surface:
    """A horizontal rectangle objects can stand on; ``clearance`` is the free height above it; ``facing`` the
    direction (radians) its furniture's front looks into the room, None where it has no front (a rug)."""

    x0: float
    y0: float
    x1: float
    y1: float
    z: float
    clearance: float = 2.0
    kind: str = "floor"
    facing: float | None = None

    @property
    def area(self) -> float:
        return (self.x1 - self.x0) * (self.y1 - self.y0)


@dataclass
class Piece:
    """One textured mesh of the room (a wall, a sofa, ...), in world coordinates."""

    mesh: Mesh
    texture: np.ndarray


@dataclass
class Room:
    width: float
    depth: float
    pieces: list[Piece] = field(default_factory=list)
    surfaces: list[Surface] = field(default_factory=list)
    footprints: list[tuple[float, float, float, float]] = field(default_factory=list)  # blocked for walking


def _boxes(specs: list[tuple[tuple[float, float, float], tuple[float, float, float]]], uv: float = 0.6) -> Mesh:
    """Merge boxes given as (size, centre) into one mesh with tiling UVs."""
    return merge([box(*size, uv_metres=uv).moved(centre) for size, centre in specs])


def _rotate_layout(specs, surfaces, w: float, d: float, quarter: int, x: float, y: float):
    """Turn a piece of furniture built facing -y in a local w x d frame by quarter turns and place it."""
    def tr(px: float, py: float) -> tuple[float, float]:
        px, py = px - w / 2, py - d / 2
        for _ in range(quarter):
            px, py = -py, px
        return x + px, y + py

    placed = []
    for (sx, sy, sz), (cx, cy, cz) in specs:
        if quarter % 2:
            sx, sy = sy, sx
        placed.append(((sx, sy, sz), (*tr(cx, cy), cz)))
    surf = []
    facing = _wrap(-np.pi / 2 + quarter * np.pi / 2)  # the local front (-y) after the quarter turns
    for s in surfaces:
        (ax, ay), (bx, by) = tr(s.x0, s.y0), tr(s.x1, s.y1)
        surf.append(Surface(min(ax, bx), min(ay, by), max(ax, bx), max(ay, by), s.z, s.clearance, s.kind, facing))
    return placed, surf


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2 * np.pi) - np.pi)


def _furniture(kind: str, rng: np.random.Generator):
    """Boxes (size, centre) in a local frame with the front at y = 0, the surfaces, and the outer size."""
    if kind == "table":
        w, d, h = rng.uniform(1.0, 1.6), rng.uniform(0.7, 0.9), 0.75
        b = [((w, d, 0.04), (w / 2, d / 2, h - 0.02))]
        b += [((0.05, 0.05, h - 0.04), (x, y, (h - 0.04) / 2)) for x in (0.05, w - 0.05) for y in (0.05, d - 0.05)]
        return b, [Surface(0.05, 0.05, w - 0.05, d - 0.05, h, 2.0, kind)], w, d
    if kind == "coffee table":
        w, d, h = rng.uniform(0.8, 1.2), rng.uniform(0.5, 0.7), 0.42
        b = [((w, d, 0.05), (w / 2, d / 2, h - 0.025)), ((w - 0.1, d - 0.1, 0.03), (w / 2, d / 2, 0.1))]
        b += [((0.05, 0.05, h), (x, y, h / 2)) for x in (0.04, w - 0.04) for y in (0.04, d - 0.04)]
        return b, [Surface(0.05, 0.05, w - 0.05, d - 0.05, h, 2.0, kind)], w, d
    if kind == "sofa":
        w, d = rng.uniform(1.6, 2.2), 0.9
        b = [((w, d - 0.2, 0.42), (w / 2, (d - 0.2) / 2, 0.21)), ((w, 0.2, 0.85), (w / 2, d - 0.1, 0.425)),
             ((0.18, d, 0.62), (0.09, d / 2, 0.31)), ((0.18, d, 0.62), (w - 0.09, d / 2, 0.31))]
        return b, [Surface(0.2, 0.05, w - 0.2, d - 0.25, 0.42, 2.0, kind)], w, d
    if kind == "bed":
        w, d = rng.uniform(1.4, 1.8), 2.0
        b = [((w, d, 0.5), (w / 2, d / 2, 0.25)), ((w, 0.08, 1.0), (w / 2, d - 0.04, 0.5)),
             ((w * 0.8, 0.35, 0.12), (w / 2, d - 0.3, 0.56))]
        return b, [Surface(0.1, 0.1, w - 0.1, d - 0.55, 0.5, 2.0, kind)], w, d
    if kind == "cabinet":
        w, d, h = rng.uniform(0.8, 1.4), 0.45, rng.uniform(0.8, 0.95)
        b = [((w, d, h), (w / 2, d / 2, h / 2)), ((w * 0.98, 0.02, h * 0.4), (w / 2, -0.005, h * 0.7))]
        return b, [Surface(0.04, 0.04, w - 0.04, d - 0.04, h, 2.0, kind)], w, d
    if kind == "nightstand":
        w, d, h = 0.5, 0.42, 0.58
        b = [((w, d, h), (w / 2, d / 2, h / 2))]
        return b, [Surface(0.04, 0.04, w - 0.04, d - 0.04, h, 2.0, kind)], w, d
    if kind == "shelf":
        w, d, h = rng.uniform(0.8, 1.2), 0.35, 1.8
        levels = [0.05, 0.45, 0.85, 1.25, 1.62]
        b = [((0.03, d, h), (0.015, d / 2, h / 2)), ((0.03, d, h), (w - 0.015, d / 2, h / 2)),
             ((w, 0.02, h), (w / 2, d - 0.01, h / 2))]
        b += [((w, d, 0.03), (w / 2, d / 2, z)) for z in levels]
        surf = [Surface(0.05, 0.04, w - 0.05, d - 0.06, z + 0.015, levels[k + 1] - z - 0.04, kind)
                for k, z in enumerate(levels[:-1])]
        return b, surf, w, d
    if kind == "tv stand":
        w, d, h = rng.uniform(1.2, 1.8), 0.45, 0.5
        b = [((w, d, h), (w / 2, d / 2, h / 2)), ((w * 0.6, 0.05, w * 0.35), (w / 2, d * 0.7, h + w * 0.175 + 0.05)),
             ((0.25, 0.2, 0.05), (w / 2, d * 0.7, h + 0.025))]
        return b, [Surface(0.04, 0.04, w * 0.18, d - 0.04, h, 2.0, kind),
                   Surface(w * 0.82, 0.04, w - 0.04, d - 0.04, h, 2.0, kind)], w, d
    raise ValueError(f"unknown furniture kind {kind!r}")


FURNITURE = ("table", "coffee table", "sofa", "bed", "cabinet", "nightstand", "shelf", "tv stand")


def _material(kind: str, rng: np.random.Generator, woods: list[np.ndarray]) -> np.ndarray:
    if kind in ("sofa", "bed"):
        return tx.fabric(rng, tx.rgb(str(rng.choice(["grey", "beige", "navy", "dark green", "maroon", "tan",
                                                     "dark grey", "light blue", "cream"]))))
    if kind == "tv stand" or rng.random() < 0.25:
        return tx.solid(tx.rgb(str(rng.choice(["white", "black", "grey", "cream"]))), rng, 4)
    return tx.wood(rng, woods[int(rng.integers(len(woods)))])


def make_room(rng: np.random.Generator) -> Room:
    """A rectangular room with a floor material, painted walls, a ceiling, a door, a window and 5-8 furniture."""
    W, D = float(rng.uniform(4.5, 6.5)), float(rng.uniform(4.5, 7.0))
    room = Room(W, D)
    woods = [tx.rgb(c) * rng.uniform(0.8, 1.1) for c in rng.choice(["tan", "brown", "beige", "dark brown"], 2)]
    floor_kind = rng.choice(["wood", "carpet", "tiles"])
    floor_tex = (tx.wood(rng, woods[0], planks=4) if floor_kind == "wood" else
                 tx.fabric(rng, tx.rgb(str(rng.choice(["beige", "grey", "khaki", "cream"])))) if floor_kind == "carpet"
                 else tx.tiles(rng, tx.rgb(str(rng.choice(["white", "cream", "grey"])))))
    room.pieces.append(Piece(box(W, D, 0.02, uv_metres=1.0).moved((W / 2, D / 2, -0.01)), floor_tex))
    room.pieces.append(Piece(box(W, D, 0.02, uv_metres=2.0).moved((W / 2, D / 2, WALL_HEIGHT + 0.01)),
                             tx.solid(tx.rgb("white"), rng, 3)))
    paint = tx.rgb(str(rng.choice(["white", "cream", "beige", "mint", "light blue", "lavender", "grey", "khaki"])))
    walls = _boxes([((W, 0.1, WALL_HEIGHT), (W / 2, -0.05, WALL_HEIGHT / 2)),
                    ((W, 0.1, WALL_HEIGHT), (W / 2, D + 0.05, WALL_HEIGHT / 2)),
                    ((0.1, D, WALL_HEIGHT), (-0.05, D / 2, WALL_HEIGHT / 2)),
                    ((0.1, D, WALL_HEIGHT), (W + 0.05, D / 2, WALL_HEIGHT / 2))], uv=1.2)
    room.pieces.append(Piece(walls, tx.wallpaper(rng, tx.shade(paint, 0.95))))
    trim = _boxes([((W, 0.02, 0.08), (W / 2, 0.01, 0.04)), ((W, 0.02, 0.08), (W / 2, D - 0.01, 0.04)),
                   ((0.02, D, 0.08), (0.01, D / 2, 0.04)), ((0.02, D, 0.08), (W - 0.01, D / 2, 0.04))])
    room.pieces.append(Piece(trim, tx.solid(tx.rgb("white"), rng, 3)))
    _wall_decor(room, rng, woods)
    _furnish(room, rng, woods)
    rug_w, rug_d = rng.uniform(1.4, 2.2), rng.uniform(1.0, 1.6)
    rx, ry = W / 2 + rng.uniform(-0.5, 0.5) - rug_w / 2, D / 2 + rng.uniform(-0.5, 0.5) - rug_d / 2
    rug = tx.pattern(str(rng.choice(["striped", "checked", "plaid", "zigzag", "plain"])),
                     tx.rgb(str(rng.choice(["maroon", "navy", "beige", "grey", "dark green"]))),
                     tx.rgb(str(rng.choice(["cream", "tan", "white"]))), rng, scale=0.4)
    room.pieces.append(Piece(box(rug_w, rug_d, 0.012).moved((rx + rug_w / 2, ry + rug_d / 2, 0.006)), rug))
    room.surfaces.append(Surface(rx + 0.1, ry + 0.1, rx + rug_w - 0.1, ry + rug_d - 0.1, 0.012, 2.0, "rug"))
    return room


def _wall_decor(room: Room, rng: np.random.Generator, woods: list[np.ndarray]) -> None:
    """A door, a window and pictures: large flat shapes that fill the frames with something besides paint."""
    W, D = room.width, room.depth
    door_x = rng.uniform(0.4, W - 1.4)
    room.pieces.append(Piece(box(0.9, 0.04, 2.05, uv_metres=2.1).moved((door_x + 0.45, 0.02, 1.025)),
                             tx.wood(rng, woods[-1] * 0.9, planks=2)))
    wy = rng.uniform(0.8, D - 2.2)
    glass = tx.solid(np.array([190, 215, 240.0]), rng, 8)
    glass[:, 124:132] = 245
    glass[124:132] = 245
    room.pieces.append(Piece(box(0.04, 1.4, 1.2).moved((W - 0.02, wy + 0.7, 1.55)), glass))
    for _ in range(int(rng.integers(1, 4))):
        art = tx.pattern(str(rng.choice(["camouflage", "floral", "striped", "polka-dot"])),
                         tx.rgb(str(rng.choice(list(tx.COLOURS)))), tx.rgb(str(rng.choice(list(tx.COLOURS)))), rng)
        art[:10], art[-10:], art[:, :10], art[:, -10:] = 30, 30, 30, 30
        w, h = rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.7)
        if rng.random() < 0.5:
            room.pieces.append(Piece(box(0.03, w, h).moved((0.015, rng.uniform(w, D - w), 1.6)), art))
        else:
            room.pieces.append(Piece(box(w, 0.03, h).moved((rng.uniform(w, W - w), D - 0.015, 1.6)), art))


def _overlaps(rect, others, margin: float) -> bool:
    x0, y0, x1, y1 = rect
    return any(x0 < b[2] + margin and b[0] < x1 + margin and y0 < b[3] + margin and b[1] < y1 + margin
               for b in others)


def _furnish(room: Room, rng: np.random.Generator, woods: list[np.ndarray]) -> None:
    """Put 5-8 pieces of furniture against the walls (tables also free-standing), 0.7 m apart at least."""
    W, D = room.width, room.depth
    kinds = ["table", "sofa", "shelf"] + [str(k) for k in rng.choice(FURNITURE, int(rng.integers(2, 6)))]
    for kind in kinds:
        boxes, surfaces, w, d = _furniture(kind, rng)
        for _ in range(30):
            free = kind in ("table", "coffee table") and rng.random() < 0.5
            quarter = int(rng.integers(4))
            fw, fd = (d, w) if quarter % 2 else (w, d)
            if free:
                x, y = rng.uniform(1.0 + fw / 2, W - 1.0 - fw / 2), rng.uniform(1.0 + fd / 2, D - 1.0 - fd / 2)
            elif quarter == 0:
                x, y = rng.uniform(fw / 2, W - fw / 2), D - fd / 2 - 0.02
            elif quarter == 2:
                x, y = rng.uniform(fw / 2, W - fw / 2), fd / 2 + 0.02
            elif quarter == 1:
                x, y = fw / 2 + 0.02, rng.uniform(fd / 2, D - fd / 2)
            else:
                x, y = W - fw / 2 - 0.02, rng.uniform(fd / 2, D - fd / 2)
            rect = (x - fw / 2, y - fd / 2, x + fw / 2, y + fd / 2)
            if rect[0] < 0 or rect[1] < 0 or rect[2] > W or rect[3] > D or _overlaps(rect, room.footprints, 0.7):
                continue
            placed, surf = _rotate_layout(boxes, surfaces, w, d, quarter, x, y)
            room.pieces.append(Piece(_boxes(placed), _material(kind, rng, woods)))
            room.surfaces.extend(surf)
            room.footprints.append(rect)
            break
    for _ in range(int(rng.integers(0, 3))):  # plants in free corners: clutter without surfaces
        x, y = rng.choice([0.35, W - 0.35]), rng.choice([0.35, D - 0.35])
        rect = (x - 0.25, y - 0.25, x + 0.25, y + 0.25)
        if _overlaps(rect, room.footprints, 0.05):
            continue
        h = rng.uniform(0.6, 1.4)
        pot = cylinder(0.16, 0.35, 16, top_radius=0.2).moved((x, y, 0))
        leaves = merge([ellipsoid(*(rng.uniform(0.12, 0.25, 3)), 10).moved((x + rng.normal(0, 0.08),
                        y + rng.normal(0, 0.08), 0.35 + rng.uniform(0.1, h))) for _ in range(6)])
        room.pieces.append(Piece(pot, tx.solid(tx.rgb(str(rng.choice(["white", "coral", "grey"]))), rng)))
        room.pieces.append(Piece(leaves, tx.fabric(rng, tx.rgb(str(rng.choice(["green", "dark green", "olive"]))))))
        room.footprints.append(rect)


Reach = Callable[[float, float, float], bool]  # whether an agent on the floor gets close enough to a point x, y, z


def place_objects(room: Room, sizes: list[tuple[float, float, float]], rng: np.random.Generator,
                  lookalikes: frozenset[int] = frozenset(), reach: Reach | None = None,
                  ) -> list[tuple[float, float, float, float]]:
    """Stand objects (radius, height, side area) on free spots of the room's surfaces: (x, y, z, yaw) each.

    Surfaces are drawn with weight sqrt(area), so big tables collect more objects than a
    nightstand, but every kind of surface gets used; shelves only take what fits under the
    next board; the rug takes no small object, which a camera 1.31 m high would never see
    larger than a speck; a small product (a bottle, an ink box, a game case, under
    ``SMALL_AREA`` seen side-on) stands on a surface at least ``SMALL_MIN_HEIGHT`` high where
    the room has one free, since on a coffee table or a sofa seat it stays under 1,500 pixels
    even from where an agent stops beside it. An object that fits on no surface (a big one in
    a room of small furniture, or one that comes after the surfaces filled up) stands on the
    floor along a wall, clear of furniture, as large objects do in a real house; the room's
    middle stays free for the camera walk. Every draw comes from ``rng``, so the result is
    still a pure function of the seeds. Only a room without any free floor along its walls is
    an error.

    The objects at the indices ``lookalikes`` (the target's same-category look-alikes; the
    target is the first object) stand at least ``LOOKALIKE_GAP`` from the target where the room
    allows it, as PIN's look-alikes stand elsewhere in the house: an agent that stops at a
    look-alike is then more than PIN's 1 m success distance from the target, a category error
    and not a success.

    Products face the room, as they stand in a house: the side the first reference view shows
    (``FRONT_AZIMUTH`` of the object) is turned to where its furniture's front looks, or away from
    the wall it stands against, give or take ``FACE_SPREAD``; on a rug, which has no front, the
    yaw is uniform.

    With ``reach``, the target and its look-alikes stand only where it holds for their centre (an
    agent standing on the floor beside the furniture can come within PIN's success distance of them),
    as PIN's episodes place the objects an agent must reach; where no spot passes, the rule is
    dropped for that object rather than the episode.
    """
    taken: list[tuple[float, float, float, float]] = []  # x, y, z, radius
    out = []
    for k, (radius, height, side_area) in enumerate(sizes):
        away = (taken[0][0], taken[0][1], LOOKALIKE_GAP) if k in lookalikes and taken else None
        near = None
        if reach is not None and (k == 0 or k in lookalikes):
            def near(x: float, y: float, z: float, half: float = height / 2) -> bool:
                return reach(x, y, z + half)
        spot = None
        for keep_away, keep_near in dict.fromkeys([(away, near), (None, near), (away, None), (None, None)]):
            spot = _spot(room, (radius, height, side_area), taken, rng, keep_away, keep_near)
            if spot is not None:
                break
        if spot is None:
            raise ValueError(f"no free surface or floor spot for an object of radius {radius:.2f} m in a "
                             f"{room.width:.1f} x {room.depth:.1f} m room")
        x, y, z, facing = spot
        taken.append((x, y, z, radius))
        turn = float(rng.uniform(-1.0, 1.0))
        out.append((x, y, z, turn * np.pi if facing is None else _wrap(facing - FRONT_AZIMUTH + turn * FACE_SPREAD)))
    return out


Away = tuple[float, float, float] | None  # (x, y, least distance) a spot must keep from, or no constraint
Spot = tuple[float, float, float, float | None]  # x, y, z and the direction the spot faces the room (or None)


def _spot(room: Room, size: tuple[float, float, float], taken: list[tuple[float, float, float, float]],
          rng: np.random.Generator, away: Away, near: Reach | None = None) -> Spot | None:
    """A surface spot (a high one first for a small product), else the floor along a wall; None if neither."""
    radius, height, side_area = size
    weights = np.array([np.sqrt(s.area) for s in room.surfaces])
    high = np.array([s.z >= SMALL_MIN_HEIGHT for s in room.surfaces])
    fits = np.array([s.clearance > height and s.x1 - s.x0 > 2 * radius and s.y1 - s.y0 > 2 * radius
                     and not (s.kind == "rug" and radius < SMALL_ON_FLOOR) for s in room.surfaces])
    spot = None
    if side_area < SMALL_AREA:
        spot = _surface_spot(room, weights * fits * high, radius, taken, rng, away, near)
    spot = spot or _surface_spot(room, weights * fits, radius, taken, rng, away, near)
    if spot is None:
        floor = _floor_spot(room, radius, taken, rng, away, near)
        spot = None if floor is None else (floor[0], floor[1], 0.0, floor[2])
    return spot


def _allowed(x: float, y: float, z: float, away: Away, near: Reach | None) -> bool:
    """Far enough from what ``away`` names, and within reach where ``near`` asks it, of a spot on a surface at z."""
    return (away is None or np.hypot(x - away[0], y - away[1]) >= away[2]) and (near is None or near(x, y, z))


def _surface_spot(room: Room, p: np.ndarray, radius: float, taken: list[tuple[float, float, float, float]],
                  rng: np.random.Generator, away: Away = None, near: Reach | None = None) -> Spot | None:
    """A free spot (x, y, z, facing) on a surface drawn with weights ``p``, clear of the objects already placed and
    where ``near`` holds; or None."""
    for _ in range(200 if p.sum() else 0):
        s = room.surfaces[int(rng.choice(len(room.surfaces), p=p / p.sum()))]
        x, y = rng.uniform(s.x0 + radius, s.x1 - radius), rng.uniform(s.y0 + radius, s.y1 - radius)
        if _allowed(x, y, s.z, away, near) and all(abs(z - s.z) > 0.05 or np.hypot(x - ox, y - oy) > radius + r + 0.02
                                    for ox, oy, z, r in taken):
            return float(x), float(y), float(s.z), s.facing
    return None


SMALL_ON_FLOOR = 0.12  # objects of a smaller radius go on furniture: seen from 1.31 m on the floor they stay specks
SMALL_AREA = 0.01  # m^2 seen side-on: a supplement bottle (0.004), an ink box (0.008), a game case (0.007)
SMALL_MIN_HEIGHT = 0.78  # cabinets and the upper shelf boards: shallow, so a camera can stand within 0.6 m
FLOOR_BANDS = (0.4, 0.8, 1.6, 100.0)  # how far from a wall a floor object may stand (metres), relaxed in turn
LOOKALIKE_GAP = 2.2  # metres between the target and a look-alike: more than PIN's 1 m success distance twice over
FRONT_AZIMUTH = np.radians(-60.0)  # the side of an object its first reference view shows (render.reference_views)
FACE_SPREAD = np.radians(45.0)  # how far a product's front may turn from the room-facing direction, either way
WALL_FACING = (np.pi / 2, -np.pi / 2, 0.0, np.pi)  # into the room from the walls y = 0, y = D, x = 0, x = W


def _floor_spot(room: Room, radius: float, taken: list[tuple[float, float, float, float]],
                rng: np.random.Generator, away: Away = None, near: Reach | None = None,
                tries: int = 500) -> tuple[float, float, float] | None:
    """A free floor position (x, y, the direction into the room from its wall) for an object of ``radius``, clear of
    furniture and other objects; None if none.

    Close to a wall first, so the room's middle stays free for the camera walk; the band
    widens only when the walls are full.
    """
    W, D = room.width, room.depth
    lo = radius + 0.05
    for band in FLOOR_BANDS:
        for _ in range(tries):
            wall, t, u = int(rng.integers(4)), rng.uniform(lo, max(W, D) - lo), rng.uniform(lo, lo + band)
            x, y = ((t, u), (t, D - u), (u, t), (W - u, t))[wall]
            if not (lo <= x <= W - lo and lo <= y <= D - lo):
                continue
            if _overlaps((x - radius, y - radius, x + radius, y + radius), room.footprints, 0.05):
                continue
            if _allowed(x, y, 0.0, away, near) and all(z > 0.05 or np.hypot(x - ox, y - oy) > radius + r + 0.02
                                                       for ox, oy, z, r in taken):
                return float(x), float(y), WALL_FACING[wall]
    return None
