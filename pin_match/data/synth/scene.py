"""Furnished houses and where objects go: rooms joined by doors, furniture with support surfaces.

A house is a row of rooms (``make_house``), each a furnished room (``make_room``) whose shared walls
open in a door 1 m wide, as PIN's houses join their rooms; the house is a pure function of its
scene seed, so every episode of one house sees the same rooms. Furniture is axis-aligned, kept
away from the room's middle and out of the doorways, so the camera walk always has a way through.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

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


Rect = tuple[float, float, float, float]  # x0, y0, x1, y1 on the floor (metres)


@dataclass
class Room:
    """A room, or a house of rooms: its floor spans ``width`` x ``depth``; ``footprints`` are blocked for walking
    (furniture, and in a house the inner walls and the floor outside a room); ``rooms`` the floor of each room."""

    width: float
    depth: float
    pieces: list[Piece] = field(default_factory=list)
    surfaces: list[Surface] = field(default_factory=list)
    footprints: list[Rect] = field(default_factory=list)
    rooms: list[Rect] = field(default_factory=list)
    keep_clear: list[Rect] = field(default_factory=list)  # doorways: free of furniture and floor objects

    def room_of(self, x: float, y: float) -> int:
        """The index of the room holding a floor point (the nearest room for a point in a doorway or a wall)."""
        rooms = self.rooms or [(0.0, 0.0, self.width, self.depth)]
        gaps = [max(x0 - x, 0.0, x - x1) + max(y0 - y, 0.0, y - y1) for x0, y0, x1, y1 in rooms]
        return int(np.argmin(gaps))

    def moved(self, dx: float) -> Room:
        """The room shifted by ``dx`` along x (where a house puts it)."""
        return Room(self.width, self.depth, [Piece(p.mesh.moved((dx, 0.0, 0.0)), p.texture) for p in self.pieces],
                    [replace(s, x0=s.x0 + dx, x1=s.x1 + dx) for s in self.surfaces],
                    [(x0 + dx, y0, x1 + dx, y1) for x0, y0, x1, y1 in self.footprints],
                    [(x0 + dx, y0, x1 + dx, y1) for x0, y0, x1, y1 in self.rooms or [(0, 0, self.width, self.depth)]],
                    [(x0 + dx, y0, x1 + dx, y1) for x0, y0, x1, y1 in self.keep_clear])


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
    facing = wrap_angle(-np.pi / 2 + quarter * np.pi / 2)  # the local front (-y) after the quarter turns
    for s in surfaces:
        (ax, ay), (bx, by) = tr(s.x0, s.y0), tr(s.x1, s.y1)
        surf.append(Surface(min(ax, bx), min(ay, by), max(ax, bx), max(ay, by), s.z, s.clearance, s.kind, facing))
    return placed, surf


def wrap_angle(angle: float) -> float:
    """An angle in [-pi, pi)."""
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


DOOR_WIDTH = 1.0  # metres: a doorway between two rooms of a house
WALL = 0.1  # a wall's thickness; two rooms of a house stand two walls apart
DOORWAY_CLEAR = 1.2  # metres into a room in front of a doorway that furniture and floor objects keep free
ROOM_SIZE = ((4.5, 6.5), (4.5, 7.0))  # a room's width and depth range (metres)
HOUSE_ROOM_SIZE = ((3.6, 4.6), (3.8, 5.0))  # a house's rooms, smaller: a house of three is PIN's scale ...
HOUSE_FURNITURE = (3, 5)  # ... with fewer pieces each (pieces a room, drawn between these, both included)


def make_room(rng: np.random.Generator, size: tuple[float, float] | None = None,
              doors: Sequence[tuple[int, float]] = (), furniture: tuple[int, int] = (5, 8)) -> Room:
    """A rectangular room with a floor material, painted walls, a ceiling, a door, a window and furniture (a table, a
    sofa, a shelf and more, ``furniture`` pieces in all, as many as fit).

    ``size`` (width, depth) is drawn from ``ROOM_SIZE`` when not given; ``doors`` are the doorways of a house,
    (side, y) each: an opening ``DOOR_WIDTH`` wide from y on the wall x = 0 (side 0) or x = width (side 1).
    """
    W, D = size if size is not None else (float(rng.uniform(*ROOM_SIZE[0])), float(rng.uniform(*ROOM_SIZE[1])))
    room = Room(W, D, rooms=[(0.0, 0.0, W, D)])
    woods = [tx.rgb(c) * rng.uniform(0.8, 1.1) for c in rng.choice(["tan", "brown", "beige", "dark brown"], 2)]
    floor_kind = rng.choice(["wood", "carpet", "tiles"])
    floor_tex = (tx.wood(rng, woods[0], planks=4) if floor_kind == "wood" else
                 tx.fabric(rng, tx.rgb(str(rng.choice(["beige", "grey", "khaki", "cream"])))) if floor_kind == "carpet"
                 else tx.tiles(rng, tx.rgb(str(rng.choice(["white", "cream", "grey"])))))
    room.pieces.append(Piece(box(W, D, 0.02, uv_metres=1.0).moved((W / 2, D / 2, -0.01)), floor_tex))
    room.pieces.append(Piece(box(W, D, 0.02, uv_metres=2.0).moved((W / 2, D / 2, WALL_HEIGHT + 0.01)),
                             tx.solid(tx.rgb("white"), rng, 3)))
    paint = tx.rgb(str(rng.choice(["white", "cream", "beige", "mint", "light blue", "lavender", "grey", "khaki"])))
    room.pieces.append(Piece(_boxes(_walls(W, D, doors), uv=1.2), tx.wallpaper(rng, tx.shade(paint, 0.95))))
    trim = _boxes([((W, 0.02, 0.08), (W / 2, 0.01, 0.04)), ((W, 0.02, 0.08), (W / 2, D - 0.01, 0.04)),
                   ((0.02, D, 0.08), (0.01, D / 2, 0.04)), ((0.02, D, 0.08), (W - 0.01, D / 2, 0.04))])
    room.pieces.append(Piece(trim, tx.solid(tx.rgb("white"), rng, 3)))
    clear = [(0.0 if side == 0 else W - DOORWAY_CLEAR, y - 0.2, DOORWAY_CLEAR if side == 0 else W, y + DOOR_WIDTH + 0.2)
             for side, y in doors]
    _wall_decor(room, rng, woods, {side for side, _ in doors})
    _furnish(room, rng, woods, furniture, clear)
    rug_w, rug_d = rng.uniform(1.4, 2.2), rng.uniform(1.0, 1.6)
    rx, ry = W / 2 + rng.uniform(-0.5, 0.5) - rug_w / 2, D / 2 + rng.uniform(-0.5, 0.5) - rug_d / 2
    rug = tx.pattern(str(rng.choice(["striped", "checked", "plaid", "zigzag", "plain"])),
                     tx.rgb(str(rng.choice(["maroon", "navy", "beige", "grey", "dark green"]))),
                     tx.rgb(str(rng.choice(["cream", "tan", "white"]))), rng, scale=0.4)
    room.pieces.append(Piece(box(rug_w, rug_d, 0.012).moved((rx + rug_w / 2, ry + rug_d / 2, 0.006)), rug))
    room.surfaces.append(Surface(rx + 0.1, ry + 0.1, rx + rug_w - 0.1, ry + rug_d - 0.1, 0.012, 2.0, "rug"))
    room.keep_clear.extend(clear)
    return room


def _walls(W: float, D: float, doors: Sequence[tuple[int, float]]) -> list:
    """The four walls as boxes (size, centre), the walls x = 0 and x = W cut around their doorways (a lintel above)."""
    boxes = [((W, WALL, WALL_HEIGHT), (W / 2, -WALL / 2, WALL_HEIGHT / 2)),
             ((W, WALL, WALL_HEIGHT), (W / 2, D + WALL / 2, WALL_HEIGHT / 2))]
    for side, x in ((0, -WALL / 2), (1, W + WALL / 2)):
        cuts = sorted(y for s, y in doors if s == side)
        y = 0.0
        for door in cuts:
            boxes.append(((WALL, door - y, WALL_HEIGHT), (x, (y + door) / 2, WALL_HEIGHT / 2)))
            boxes.append(((WALL, DOOR_WIDTH, WALL_HEIGHT - 2.05), (x, door + DOOR_WIDTH / 2, (WALL_HEIGHT + 2.05) / 2)))
            y = door + DOOR_WIDTH
        boxes.append(((WALL, D - y, WALL_HEIGHT), (x, (y + D) / 2, WALL_HEIGHT / 2)))
    return boxes


def make_house(rng: np.random.Generator, rooms: int) -> Room:
    """``rooms`` furnished rooms in a row along x, each joined to the next by a doorway through their shared walls.

    The house is one ``Room`` spanning all of them: the walls between rooms and the floor beyond a shorter room are
    footprints (nothing walks there), ``rooms`` holds each room's floor, and a floor board fills each doorway.
    """
    sizes = [(float(rng.uniform(*HOUSE_ROOM_SIZE[0])), float(rng.uniform(*HOUSE_ROOM_SIZE[1]))) for _ in range(rooms)]
    doors = [float(rng.uniform(0.4, min(a[1], b[1]) - DOOR_WIDTH - 0.4)) for a, b in zip(sizes, sizes[1:])]
    depth = max(d for _, d in sizes)
    house = Room(0.0, depth)
    x = 0.0
    for k, (w, d) in enumerate(sizes):
        own = [(0, doors[k - 1])] if k else []
        own += [(1, doors[k])] if k < rooms - 1 else []
        room = make_room(rng, (w, d), own, HOUSE_FURNITURE).moved(x)
        house.pieces += room.pieces
        house.surfaces += room.surfaces
        house.footprints += room.footprints
        house.keep_clear += room.keep_clear
        house.rooms += room.rooms
        if d < depth:
            house.footprints.append((x - 2 * WALL, d, x + w + 2 * WALL, depth))
        if k < rooms - 1:
            y = doors[k]
            house.footprints += [(x + w, 0.0, x + w + 2 * WALL, y), (x + w, y + DOOR_WIDTH, x + w + 2 * WALL, depth)]
            house.pieces.append(Piece(box(2 * WALL, DOOR_WIDTH, 0.02, uv_metres=1.0).moved(
                (x + w + WALL, y + DOOR_WIDTH / 2, -0.01)), room.pieces[0].texture))
        x += w + 2 * WALL
    house.width = x - 2 * WALL
    return house


def _wall_decor(room: Room, rng: np.random.Generator, woods: list[np.ndarray], door_sides: set[int]) -> None:
    """A door, a window and pictures: large flat shapes that fill the frames with something besides paint. The window
    and pictures keep off a wall with a doorway (``door_sides``: 0 the wall x = 0, 1 the wall x = W)."""
    W, D = room.width, room.depth
    door_x = rng.uniform(0.4, W - 1.4)
    room.pieces.append(Piece(box(0.9, 0.04, 2.05, uv_metres=2.1).moved((door_x + 0.45, 0.02, 1.025)),
                             tx.wood(rng, woods[-1] * 0.9, planks=2)))
    wy = rng.uniform(0.8, D - 2.2)
    glass = tx.solid(np.array([190, 215, 240.0]), rng, 8)
    glass[:, 124:132] = 245
    glass[124:132] = 245
    window = box(0.04, 1.4, 1.2).moved((W - 0.02, wy + 0.7, 1.55)) if 1 not in door_sides else \
        box(1.4, 0.04, 1.2).moved((min(wy, W - 1.6) + 0.7, D - 0.02, 1.55))
    room.pieces.append(Piece(window, glass))
    for _ in range(int(rng.integers(1, 4))):
        art = tx.pattern(str(rng.choice(["camouflage", "floral", "striped", "polka-dot"])),
                         tx.rgb(str(rng.choice(list(tx.COLOURS)))), tx.rgb(str(rng.choice(list(tx.COLOURS)))), rng)
        art[:10], art[-10:], art[:, :10], art[:, -10:] = 30, 30, 30, 30
        w, h = rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.7)
        if rng.random() < 0.5 and 0 not in door_sides:
            room.pieces.append(Piece(box(0.03, w, h).moved((0.015, rng.uniform(w, D - w), 1.6)), art))
        else:
            room.pieces.append(Piece(box(w, 0.03, h).moved((rng.uniform(w, W - w), D - 0.015, 1.6)), art))


def overlaps(rect, others, margin: float) -> bool:
    """Does the rectangle come within ``margin`` of any of ``others`` (x0, y0, x1, y1 each)?"""
    x0, y0, x1, y1 = rect
    return any(x0 < b[2] + margin and b[0] < x1 + margin and y0 < b[3] + margin and b[1] < y1 + margin
               for b in others)


def _furnish(room: Room, rng: np.random.Generator, woods: list[np.ndarray], count: tuple[int, int],
             clear: Sequence[Rect] = ()) -> None:
    """Put ``count`` (fewest, most) pieces of furniture against the walls (tables also free-standing), 0.7 m apart at
    least and off the doorways' ``clear`` rectangles."""
    W, D = room.width, room.depth
    base = ["table", "sofa", "shelf"]
    kinds = base + [str(k) for k in rng.choice(FURNITURE, int(rng.integers(count[0] - 3, count[1] - 2)))]
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
            if rect[0] < 0 or rect[1] < 0 or rect[2] > W or rect[3] > D or overlaps(rect, room.footprints, 0.7) \
                    or overlaps(rect, clear, 0.0):
                continue
            placed, surf = _rotate_layout(boxes, surfaces, w, d, quarter, x, y)
            room.pieces.append(Piece(_boxes(placed), _material(kind, rng, woods)))
            room.surfaces.extend(surf)
            room.footprints.append(rect)
            break
    for _ in range(int(rng.integers(0, 3))):  # plants in free corners: clutter without surfaces
        x, y = rng.choice([0.35, W - 0.35]), rng.choice([0.35, D - 0.35])
        rect = (x - 0.25, y - 0.25, x + 0.25, y + 0.25)
        if overlaps(rect, room.footprints, 0.05) or overlaps(rect, clear, 0.0):
            continue
        h = rng.uniform(0.6, 1.4)
        pot = cylinder(0.16, 0.35, 16, top_radius=0.2).moved((x, y, 0))
        leaves = merge([ellipsoid(*(rng.uniform(0.12, 0.25, 3)), 10).moved((x + rng.normal(0, 0.08),
                        y + rng.normal(0, 0.08), 0.35 + rng.uniform(0.1, h))) for _ in range(6)])
        room.pieces.append(Piece(pot, tx.solid(tx.rgb(str(rng.choice(["white", "coral", "grey"]))), rng)))
        room.pieces.append(Piece(leaves, tx.fabric(rng, tx.rgb(str(rng.choice(["green", "dark green", "olive"]))))))
        room.footprints.append(rect)
