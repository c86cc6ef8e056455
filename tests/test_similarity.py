"""Intra/inter-category similarity with a toy matcher whose embeddings are set by hand."""

from __future__ import annotations

import numpy as np
import pytest
from toys import HandSet

from pin_match.evaluation.core.similarity import similarity, similarity_tables, write_similarity

# val objects of the tiny frame-set; lengths differ on purpose (cosine must normalise)
EMBEDDINGS = {"mug_c": [1.0, 0.0, 0.0], "mug_d": [3.0, 4.0, 0.0], "ball_b": [0.6, 0.0, 0.8]}


def test_similarity_by_hand(tiny_frameset, tmp_path):
    stub = HandSet(embeddings={tiny_frameset.target(o).views[0].tobytes(): e for o, e in EMBEDDINGS.items()})
    table, matrix = similarity(tiny_frameset, stub, split="val")
    # unit vectors: c = (1,0,0), d = (.6,.8,0), b = (.6,0,.8); cos(c,d) = .6, cos(c,b) = .6, cos(d,b) = .36
    assert table.loc["mug", "intra"] == pytest.approx(0.6)
    assert table.loc["mug", "inter"] == pytest.approx((0.6 + 0.36) / 2)
    assert np.isnan(table.loc["ball", "intra"])  # a single ball: no pair, undefined
    assert table.loc["ball", "inter"] == pytest.approx(0.48)
    assert matrix.loc["mug", "ball"] == pytest.approx(0.48) == matrix.loc["ball", "mug"]
    assert list(table.n_objects) == [1, 2]
    files = write_similarity(table, matrix, tmp_path / "sim", title="stub, val")
    assert all(f.stat().st_size > 0 for f in files)
    assert "| mug | 2 | 0.6 | 0.48 |" in (tmp_path / "sim" / "similarity.md").read_text()


def test_similarity_tables_pair_weighting():
    # categories x: 2 objects, y: 3 objects, z: 1; cosine = 1 within x, .5 within y, .1 everywhere else
    cats = np.array(["x", "x", "y", "y", "y", "z"])
    cos = np.full((6, 6), 0.1)
    cos[:2, :2], cos[2:5, 2:5] = 1.0, 0.5
    np.fill_diagonal(cos, 1.0)
    table, _ = similarity_tables(cats, cos)
    assert table.loc["x", "intra"] == pytest.approx(1.0) and table.loc["y", "intra"] == pytest.approx(0.5)
    assert table.loc["z", "inter"] == pytest.approx(0.1) and np.isnan(table.loc["z", "intra"])
