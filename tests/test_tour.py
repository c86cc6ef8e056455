"""The tour of the whole house (``synth.tour.exploration_walk``), without rendering: it reads the house and never the
target, stands at every viewpoint, looks at every piece close, enters every room once and ends when it is done, one
PIN action a pose."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pin_match.data.agent import CAMERA_HEIGHT, FORWARD_STEP, HALF_HFOV, HALF_VFOV, TURN
from pin_match.data.synth import SynthSize, tour
from pin_match.data.synth.placing import place_objects
from pin_match.data.synth.scene import Room, Surface, make_house
from pin_match.data.synth.walk import Grid

ROOMS = SynthSize().rooms  # the default set's houses
LIMIT = 1000  # PIN's episode limit: the budget the generator passes


def _house(seed: int) -> Room:
    return make_house(np.random.default_rng(seed), ROOMS)


def _framed(walk: list, points: np.ndarray) -> np.ndarray:
    """Per point, the 3D distance from the nearest pose whose view holds it (inf where none does)."""
    w = np.array(walk)
    dx, dy = points[None, :, 0] - w[:, None, 0], points[None, :, 1] - w[:, None, 1]
    flat = np.hypot(dx, dy)
    bearing = np.abs((np.arctan2(dy, dx) - w[:, None, 2] + np.pi) % (2 * np.pi) - np.pi)
    elevation = np.arctan2(points[None, :, 2] - CAMERA_HEIGHT, flat) - w[:, None, 3]
    inside = (bearing <= HALF_HFOV) & (np.abs(elevation) <= HALF_VFOV)
    return np.where(inside, np.hypot(flat, points[None, :, 2] - CAMERA_HEIGHT), np.inf).min(0)


@pytest.mark.parametrize("seed", range(4))
def test_the_tour_stands_at_every_viewpoint_and_ends_when_done(seed):
    """Every viewpoint of the house's reachable floor is stood on; the tour ends after the last one, well within
    PIN's 1,000 steps, the same with a larger budget (it is done, not cut off)."""
    house = _house(seed)
    grid = Grid(house, list(house.footprints))
    views = tour._viewpoints(house, grid, {tuple(int(v) for v in c) for c in grid.main_floor()})
    walk = tour.exploration_walk(house, list(house.footprints), [], LIMIT, np.random.default_rng(seed))
    stood = np.array([pose[:2] for pose in walk])
    assert all(np.hypot(*(stood - grid.centre(view.cell)).T).min() <= 0.05 + 1e-9 for view in views)  # go_to's stop
    assert len(views) >= sum(p.kind != "floor" for p in tour._pieces(house))  # one at least per piece
    assert 100 < len(walk) < 0.6 * LIMIT
    assert walk == tour.exploration_walk(house, list(house.footprints), [], 10 * LIMIT, np.random.default_rng(seed))
    assert walk[:50] == tour.exploration_walk(house, list(house.footprints), [], 50, np.random.default_rng(seed))


FARTHEST, WITHIN_COVER, FLOOR_WITHIN = 2.0, 0.94, 0.99  # the bars: metres, shares of points


def _looked_at(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The distance at which the tour of house ``seed`` frames each point of its furniture and rugs, and of its
    floor along the walls (``_framed``)."""
    house = _house(seed)
    walk = tour.exploration_walk(house, list(house.footprints), [], LIMIT, np.random.default_rng(seed))
    furniture = np.concatenate([p.points for p in tour._pieces(house) if p.kind != "floor"])
    floor = np.concatenate([p.points for p in tour._pieces(house) if p.kind == "floor"])
    return _framed(walk, furniture), _framed(walk, floor)


@pytest.mark.parametrize("seed", range(4))
def test_every_piece_and_every_rug_is_looked_at_close(seed):
    """Every point of every piece of furniture and every rug, where an object's middle would stand, is in the view of
    some pose (its tilt included) within 2 m, and nine in ten within ``COVER``; the floor along the walls, where
    only large objects stand, within ``FLOOR_COVER``. The bars sit outside the spread over seeds 0-7: the farthest
    point 1.67-1.94 m, the share within ``COVER`` 0.950-0.990, the floor's 1.000 at every seed."""
    house = _house(seed)
    furniture = np.concatenate([p.points for p in tour._pieces(house) if p.kind != "floor"])
    rugs = [s for s in house.surfaces if s.facing is None]
    assert len(rugs) == ROOMS and all(((furniture[:, 0] >= s.x0) & (furniture[:, 0] <= s.x1) & (furniture[:, 1] >= s.y0)
                                       & (furniture[:, 1] <= s.y1) & (furniture[:, 2] < 0.2)).any() for s in rugs)
    near, floor = _looked_at(seed)
    assert near.max() <= FARTHEST and (near <= tour.COVER).mean() >= WITHIN_COVER, np.sort(near)[-5:]
    assert (floor <= tour.FLOOR_COVER).mean() >= FLOOR_WITHIN


@pytest.mark.parametrize("broken, value", [("SIDE", np.radians(3)), ("MIN_SHARE", 0.5), ("FLOOR_SHARE", 0.9)])
def test_a_broken_tour_falls_below_the_bars(monkeypatch, broken, value):
    """A tour that keeps its points only 3 degrees inside the frame's sides (less than the walker's turn slack), and
    ones that skip the spots seeing under half of a piece or most of a floor: each leaves some house of seeds 0-3
    below a bar above."""
    monkeypatch.setattr(tour, broken, value)
    looked = [_looked_at(seed) for seed in range(4)]
    assert any(near.max() > FARTHEST or (near <= tour.COVER).mean() < WITHIN_COVER
               or (floor <= tour.FLOOR_COVER).mean() < FLOOR_WITHIN for near, floor in looked), \
        [(near.max(), (near <= tour.COVER).mean(), (floor <= tour.FLOOR_COVER).mean()) for near, floor in looked]


@pytest.mark.parametrize("seed", range(4))
def test_one_pin_action_a_pose(seed):
    """Each pose differs from the one before by one action: a step of at most 0.25 m, a turn of at most 30 degrees
    or a tilt of 30 degrees; tilts are PIN's, level or 30 or 60 degrees down, and the walk is level while it moves."""
    house = _house(seed)
    walk = tour.exploration_walk(house, list(house.footprints), [], LIMIT, np.random.default_rng(seed))
    for (ax, ay, ayaw, ap), (bx, by, byaw, bp) in zip(walk, walk[1:]):
        moved = np.hypot(bx - ax, by - ay)
        turned = abs(np.angle(np.exp(1j * (byaw - ayaw))))
        tilted = abs(bp - ap)
        changes = (moved > 1e-9) + (turned > 1e-9) + (tilted > 1e-9)
        assert changes == 1, (ax, ay, ayaw, ap, bx, by, byaw, bp)
        assert moved <= FORWARD_STEP + 1e-9 and turned <= TURN + 1e-9 and tilted in (0.0, pytest.approx(np.radians(30)))
        assert moved < 1e-9 or bp == 0.0
    assert {round(float(np.degrees(p))) for *_, p in walk} <= {0, -30, -60}


@pytest.mark.parametrize("seed", range(4))
def test_the_tour_enters_every_room_once(seed):
    """Room by room: the rooms the poses stand in, in order, are each room once, from the start's room at one end of
    the row to the other end, never back through a doorway."""
    house = _house(seed)
    walk = tour.exploration_walk(house, list(house.footprints), [], LIMIT, np.random.default_rng(seed))
    rooms = [k for k, _ in itertools.groupby(house.room_of(x, y) for x, y, _, _ in walk)]
    assert rooms in ([0, 1, 2], [2, 1, 0]), rooms


@pytest.mark.parametrize("seed", range(3))
def test_the_tour_reads_no_target(seed):
    """The generator passes every annotated object as ``away_from``: whichever of them is the target (listed first
    or last), the tour is the same, and it starts at one end of the house, two metres of walk or more from each."""
    house = _house(seed)
    rng = np.random.default_rng(seed + 10)
    spots = place_objects(house, [(0.08, 0.2, 0.02)] * 9, rng)
    obstacles = list(house.footprints) + [(x - 0.1, y - 0.1, x + 0.1, y + 0.1) for x, y, z, _ in spots if z < 0.05]
    objects = [(x, y) for x, y, _, _ in spots]
    walks = [tour.exploration_walk(house, obstacles, order, LIMIT, np.random.default_rng(seed))
             for order in (objects, objects[::-1], objects[3:] + objects[:3])]
    assert walks[0] == walks[1] == walks[2]
    assert house.room_of(*walks[0][0][:2]) in (0, ROOMS - 1)
    assert len({house.room_of(x, y) for x, y, _, _ in walks[0]}) == ROOMS


def _one_table(width: float, blocked: list[tuple[float, float, float, float]]) -> Room:
    """A room ``width`` x 5 m with one table (1.2 x 0.8 m), front facing -y, and obstacles ``blocked``."""
    table = Surface(1.95, 2.05, 3.05, 2.75, 0.75, kind="table", facing=-np.pi / 2)
    return Room(width, 5.0, surfaces=[table], footprints=[(1.9, 2.0, 3.1, 2.8), *blocked])


def test_a_piece_with_its_front_blocked_is_seen_from_its_side_and_one_boxed_in_is_skipped():
    """A table whose front is blocked is looked at from its sides or back instead; one with no free floor within
    ``VIEW_FAR`` of it is skipped, and the tour still ends."""
    room = _one_table(5.0, [(1.0, 0.0, 4.0, 2.0)])  # the floor in front of the table blocked, wall to wall
    walk = tour.exploration_walk(room, room.footprints, [], LIMIT, np.random.default_rng(0))
    table = room.surfaces[0]
    beside = [(x, y) for x, y, _, _ in walk if np.hypot(max(table.x0 - x, 0, x - table.x1),
                                                        max(table.y0 - y, 0, y - table.y1)) <= tour.VIEW_FAR]
    assert beside and all(y > 2.0 for _, y in beside)  # never in front: from the sides or behind
    points = np.array([[x, y, table.z + tour.LOOK_ABOVE] for x in np.linspace(table.x0, table.x1, 5)
                       for y in np.linspace(table.y0, table.y1, 4)])
    assert (_framed(walk, points) <= 2.0).all()
    room = _one_table(8.0, [(0.0, 0.0, 4.8, 2.0), (0.0, 2.0, 1.9, 5.0), (3.1, 2.0, 4.8, 5.0), (1.9, 2.8, 3.1, 5.0)])
    grid = Grid(room, room.footprints)  # free floor only 2 m and more from the table
    views = tour._viewpoints(room, grid, {tuple(int(v) for v in c) for c in grid.main_floor()})
    assert views and all(grid.centre(v.cell)[0] > 4.8 for v in views)  # the floor's only
    assert len(tour.exploration_walk(room, room.footprints, [], LIMIT, np.random.default_rng(0))) < LIMIT


def test_a_shelf_is_looked_into_from_its_front_at_every_board():
    """A shelf's side panels and back are solid: every board's middle is in the view of a pose that stands in front
    of it, within ``COVER`` (a tilt down for the low boards)."""
    boards = [Surface(2.05, 4.5, 2.95, 4.75, z, kind="shelf", facing=-np.pi / 2) for z in (0.065, 0.465, 0.865, 1.265)]
    room = Room(5.0, 5.0, surfaces=boards, footprints=[(2.0, 4.45, 3.0, 4.8)])
    walk = tour.exploration_walk(room, room.footprints, [], LIMIT, np.random.default_rng(1))
    ahead = [pose for pose in walk if 4.5 - pose[1] >= tour.SHELF_AHEAD and abs(pose[0] - 2.5) - 0.45 <= 4.5 - pose[1]]
    points = np.array([[2.5, 4.6, s.z + tour.LOOK_ABOVE] for s in boards])
    assert (_framed(ahead, points) <= tour.COVER).all()
    assert min(p for *_, p in ahead) < 0  # the low boards take a look down
