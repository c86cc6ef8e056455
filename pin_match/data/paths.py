"""Shortest walks on a grid of standable cells: the one path engine every distance of the benchmark is measured on.

The agent's floor map (``geometry.FloorMap``: SPL's geodesic, the walk to a goal, the walk-ups) and the
generator's walking grid (``synth.walk.Grid``: the tour and the walk that seeks the target) are both a boolean
grid of cells an agent's body fits in; each is walked here, on one graph: an edge between 8-neighbours, a
straight step one cell long, a diagonal sqrt(2) cells (Dijkstra, ``scipy.sparse.csgraph``).
"""

from __future__ import annotations

import math

import numpy as np

STEPS = ((1, 0), (0, 1), (1, 1), (1, -1))  # each 8-neighbour pair once: the graph's edges are symmetric


class GridWalks:
    """The standable cells of ``free`` (``free[i, j]``: cell i along x, j along y, ``cell`` metres a side) as a graph,
    numbered in ``np.argwhere(free)`` order; shortest walks from a cell are kept, as a sweep asks the same few sources
    again and again."""

    def __init__(self, free: np.ndarray, cell: float) -> None:
        from scipy.sparse import coo_matrix

        self.free, self.cell = free, float(cell)
        self.cells = np.argwhere(free)
        self.node = np.full(free.shape, -1, np.int64)
        self.node[self.cells[:, 0], self.cells[:, 1]] = np.arange(len(self.cells))
        rows, cols, weights = [], [], []
        for di, dj in STEPS:
            ni, nj = self.cells[:, 0] + di, self.cells[:, 1] + dj
            inside = (ni >= 0) & (ni < free.shape[0]) & (nj >= 0) & (nj < free.shape[1])
            other = np.full(len(self.cells), -1, np.int64)
            other[inside] = self.node[ni[inside], nj[inside]]
            ok = other >= 0
            rows.append(np.flatnonzero(ok))
            cols.append(other[ok])
            weights.append(np.full(int(ok.sum()), self.cell * (math.sqrt(2.0) if di and dj else 1.0)))
        r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(weights)
        self.graph = coo_matrix((np.r_[w, w], (np.r_[r, c], np.r_[c, r])),
                                shape=(len(self.cells), len(self.cells))).tocsr()
        self._from: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._parts: np.ndarray | None = None

    def parts(self) -> np.ndarray:
        """Each cell's connected part of the floor, numbered in the order of each part's first cell."""
        if self._parts is None:
            from scipy.sparse.csgraph import connected_components

            self._parts = connected_components(self.graph, directed=False)[1]
        return self._parts

    def largest_part(self) -> np.ndarray:
        """The cells (numbers, ascending) of the largest connected part: the first of equals."""
        parts = self.parts()
        return np.flatnonzero(parts == np.bincount(parts).argmax())

    def from_node(self, source: int) -> tuple[np.ndarray, np.ndarray]:
        """Walk lengths (metres) from the cell numbered ``source`` to every cell (inf where none joins them), and
        each cell's predecessor on its shortest walk (negative at the source and where unreachable)."""
        from scipy.sparse.csgraph import dijkstra

        if source not in self._from:
            self._from[source] = dijkstra(self.graph, indices=source, return_predecessors=True)
        return self._from[source]

    def from_nodes(self, sources: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """Per cell, the least of ``offsets[k]`` plus the walk from cell ``sources[k]``: a walk that ends with a
        stretch off the grid (to a point on furniture, from the cells within reach of it)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra

        n, grid = len(self.cells), self.graph.tocoo()
        entry = n  # one more node, joined to each source by its offset: the walks' common start
        rows = np.r_[grid.row, np.full(len(sources), entry)]
        cols = np.r_[grid.col, np.asarray(sources, np.int64)]
        graph = coo_matrix((np.r_[grid.data, np.asarray(offsets, np.float64)], (rows, cols)), shape=(n + 1, n + 1))
        return dijkstra(graph.tocsr(), indices=entry)[:n]

    def path(self, source: int, goal: int) -> list[int]:
        """The cells of the shortest walk from ``source`` to ``goal``, both included; [] where none joins them."""
        lengths, parents = self.from_node(source)
        if not np.isfinite(lengths[goal]):
            return []
        cells = [goal]
        while cells[-1] != source:
            cells.append(int(parents[cells[-1]]))
        return cells[::-1]

    def on_grid(self, lengths: np.ndarray) -> np.ndarray:
        """Per-cell lengths laid out on the grid (inf on cells that are not standable)."""
        out = np.full(self.free.shape, np.inf)
        out[self.cells[:, 0], self.cells[:, 1]] = lengths
        return out
