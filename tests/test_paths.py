"""The one path engine (``pin_match.data.paths``): shortest walks on a grid of standable cells, by hand."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pin_match.data.geometry import FloorMap
from pin_match.data.paths import GridWalks

PACKAGE = Path(__file__).resolve().parents[1] / "pin_match"


def test_a_walk_round_a_wall_by_hand():
    """A wall at x 5 from y 0 to 7 on 1 m cells: from (2, 0) to (8, 0) each half is 3 diagonal and 5 straight cells."""
    free = np.ones((10, 10), bool)
    free[5, :8] = False
    walks = GridWalks(free, 1.0)
    source, goal = walks.node[2, 0], walks.node[8, 0]
    assert walks.from_node(source)[0][goal] == pytest.approx(10 + 6 * math.sqrt(2))
    cells = [tuple(walks.cells[c]) for c in walks.path(source, goal)]
    assert cells[0] == (2, 0) and cells[-1] == (8, 0) and (5, 8) in cells
    assert all(max(abs(a - c), abs(b - d)) == 1 for (a, b), (c, d) in zip(cells, cells[1:]))  # 8-neighbours
    assert walks.on_grid(walks.from_node(source)[0])[5, 3] == np.inf  # the wall is no cell


def test_a_walk_from_several_starts_takes_each_start_s_offset():
    """On a 1 x 5 corridor of 0.5 m cells, starts at cell 0 (offset 2.0) and cell 4 (offset 0.2): cell 1 is 0.5 from
    the first (2.5) and 1.5 from the second (1.7), so the second wins there, the first at its own cell (2.0 against
    2.2); a start with offset 0 counts from 0."""
    walks = GridWalks(np.ones((5, 1), bool), 0.5)
    lengths = walks.from_nodes(np.array([0, 4]), np.array([2.0, 0.2]))
    np.testing.assert_allclose(lengths, [2.0, 1.7, 1.2, 0.7, 0.2])
    np.testing.assert_allclose(walks.from_nodes(np.array([2]), np.array([0.0])), [1.0, 0.5, 0.0, 0.5, 1.0])
    apart = GridWalks(np.array([[True], [False], [True]]), 1.0)
    assert apart.path(0, 1) == [] and apart.from_node(0)[0][1] == np.inf


def test_parts_join_diagonal_neighbours_and_the_largest_is_the_first_of_equals():
    """A 4 x 4 grid: cells (0, 0) and (1, 1) touch at a corner (one part), (3, 0) stands alone, and (0, 3), (1, 3)
    and (3, 3) make a part of two and a part of one. The largest parts tie at two cells: the first, by its first
    cell, is the largest; a third cell on the later one makes that one the largest."""
    free = np.zeros((4, 4), bool)
    free[[0, 1, 3, 0, 1, 3], [0, 1, 0, 3, 3, 3]] = True
    walks = GridWalks(free, 1.0)
    parts = {tuple(int(v) for v in c): int(p) for c, p in zip(walks.cells, walks.parts())}
    assert parts[0, 0] == parts[1, 1] and parts[0, 3] == parts[1, 3]
    assert len({parts[0, 0], parts[0, 3], parts[3, 0], parts[3, 3]}) == 4
    assert [tuple(int(v) for v in walks.cells[c]) for c in walks.largest_part()] == [(0, 0), (1, 1)]
    free[2, 3] = True
    joined = GridWalks(free, 1.0)
    assert [tuple(int(v) for v in joined.cells[c]) for c in joined.largest_part()] == [(0, 3), (1, 3), (2, 3), (3, 3)]


def test_the_floor_map_and_the_generator_s_grid_walk_on_one_engine():
    """SPL's geodesic (the floor map) and the tour's distances (``synth.walk.Grid``) come from the same graph."""
    from pin_match.data.synth.scene import make_house
    from pin_match.data.synth.walk import CELL, Grid

    house = make_house(np.random.default_rng(0), 3)
    grid = Grid(house, list(house.footprints))
    floor = FloorMap(grid.free, CELL)
    a, b = np.argwhere(grid.free)[[0, -1]]
    expected = grid.path_lengths(tuple(a))[tuple(b)]
    assert np.isfinite(expected)
    assert floor.walk_length((a + 0.5) * CELL, (b + 0.5) * CELL) == pytest.approx(expected, abs=1e-12)


def test_the_engine_is_the_one_module_that_searches_a_graph():
    searching = sorted(p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")
                       if any(word in p.read_text() for word in ("dijkstra", "heapq", "deque(")))
    assert searching == ["data/paths.py"]
