"""Where an episode's objects go in a furnished house: on the furniture's surfaces and rugs where they fit and an
agent on the floor can get near them, else on the floor along the walls, each product turned to show its front to
the room, look-alikes kept apart from the target.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from pin_match.data.synth.scene import Room, overlaps, wrap_angle

Reach = Callable[[float, float, float], bool]  # whether an agent on the floor gets close enough to a point x, y, z


def place_objects(room: Room, sizes: list[tuple[float, float, float]], rng: np.random.Generator,
                  families: Sequence[int | None] = (), reach: Reach | None = None,
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

    ``families`` labels the annotated objects (the first ``len(families)`` of ``sizes``; None: not
    annotated): two of one family (a target and its look-alike, whichever is the target) stand at
    least ``LOOKALIKE_GAP`` apart where the house allows it, as PIN's look-alikes stand elsewhere in
    the house: an agent that stops at a look-alike is then more than PIN's 1 m success distance from
    the target, a category error and not a success.

    Products face the room, as they stand in a house: the side the first reference view shows
    (``FRONT_AZIMUTH`` of the object) is turned to where its furniture's front looks, or away from
    the wall it stands against, give or take ``FACE_SPREAD``; on a rug, which has no front, the
    yaw is uniform.

    With ``reach``, the annotated objects stand only where it holds for their centre (an
    agent standing on the floor beside the furniture can come within PIN's success distance of them),
    as PIN's episodes place the objects an agent must reach; where no spot passes, the rule is
    dropped for that object rather than the episode.
    """
    taken: list[tuple[float, float, float, float]] = []  # x, y, z, radius
    out = []
    for k, (radius, height, side_area) in enumerate(sizes):
        family = families[k] if k < len(families) else None
        away = tuple((x, y) for (x, y, _, _), f in zip(taken, families) if f is not None and f == family) or None
        near = None
        if reach is not None and family is not None:
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
        front = turn * np.pi if facing is None else wrap_angle(facing - FRONT_AZIMUTH + turn * FACE_SPREAD)
        out.append((x, y, z, front))
    return out


Away = tuple[tuple[float, float], ...] | None  # points (x, y) a spot keeps LOOKALIKE_GAP from, or no constraint
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
    return (away is None or all(np.hypot(x - ax, y - ay) >= LOOKALIKE_GAP for ax, ay in away)) and \
        (near is None or near(x, y, z))


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
            spot = (x - radius, y - radius, x + radius, y + radius)
            if overlaps(spot, room.footprints, 0.05) or overlaps(spot, room.keep_clear, 0.0):
                continue
            if _allowed(x, y, 0.0, away, near) and all(z > 0.05 or np.hypot(x - ox, y - oy) > radius + r + 0.02
                                                       for ox, oy, z, r in taken):
                return float(x), float(y), WALL_FACING[wall]
    return None
