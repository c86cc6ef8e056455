"""Figures per band of the objects' pixel area (``evaluation.core.sizes``): hand-computed on a small table, then the
files ``report`` and ``compare`` write with them."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pin_match.evaluation import Bootstrap, EvalContext
from pin_match.evaluation.core.metrics import detection_metrics, frame_arrays
from pin_match.evaluation.core.sizes import (
    ALL,
    BANDS,
    NO_OBJECT,
    bands_of,
    best_point_hits,
    class_pixels,
    paired_size_rows,
    readable,
    size_table,
)
from pin_match.evaluation.pages.sizes_page import sizes_section
from pin_match.scoring.table import ScoreTable

# (episode, step): (score, {role: [pixels of each object of that role]}) -- step order within each episode
FRAMES = {
    ("A", 0): (0.9, {"target": [500]}),
    ("A", 1): (0.95, {"same_category": [800]}),
    ("A", 2): (0.3, {"target": [1500]}),
    ("A", 3): (0.6, {"same_category": [1200, 400], "other": [6000]}),  # a look-alike frame: its largest look-alike
    ("A", 4): (0.7, {"other": [3000]}),
    ("A", 5): (0.8, {}),
    ("B", 0): (0.6, {"other": [7000]}),
    ("B", 1): (0.4, {"target": [6000], "same_category": [300]}),  # a target frame: the target's area
    ("B", 2): (0.2, {"same_category": [5500]}),
    ("B", 3): (0.1, {"target": [900]}),
}
HITS = {"A_0": True, "A_2": False, "B_1": True, "B_3": False}  # does the best point of each target frame lie on it
SIGMA = 0.5


def scored_and_visibility(scores: dict | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    rows, vis = [], []
    for (episode, step), (score, objects) in FRAMES.items():
        frame_id = f"{episode}_{step}"
        rows.append(dict(frame_id=frame_id, episode_id=episode, step=step, target_category="mug",
                         target_visible="target" in objects, same_visible="same_category" in objects,
                         other_visible="other" in objects, target_seen=0.0,
                         score=(scores or {}).get(frame_id, score)))
        for role, areas in objects.items():
            vis += [dict(frame_id=frame_id, role=role, mask_value=len(vis) + 1, pixels=a) for a in areas]
    return pd.DataFrame(rows), pd.DataFrame(vis)


def hits_table() -> pd.DataFrame:
    return pd.DataFrame([(f, True, h) for f, h in HITS.items()], columns=["frame_id", "has_point", "hit"])


def test_each_frame_takes_the_area_of_the_object_that_decides_its_class():
    scored, vis = scored_and_visibility()
    pixels = dict(zip(scored.frame_id, class_pixels(scored, vis)))
    assert pixels == {"A_0": 500, "A_1": 800, "A_2": 1500, "A_3": 1200, "A_4": 3000, "A_5": 0, "B_0": 7000,
                      "B_1": 6000, "B_2": 5500, "B_3": 900}
    assert bands_of(np.array([0, 1, 999, 1000, 1999, 2000, 4999, 5000, 10 ** 6])).tolist() == [
        NO_OBJECT, 0, 0, 1, 1, 2, 2, 3, 3]


def test_size_table_by_hand():
    scored, vis = scored_and_visibility()
    table = size_table(scored, vis, SIGMA, hits_table())
    assert list(table.index) == [*BANDS, ALL]
    expected = {  # n_target, n_same, auroc_same, n_matched, tm, cm, recall, n_first, fm-prec, localisation
        "< 1,000": (2, 1, 0.0, 2, 50.0, 50.0, 50.0, 1, 100.0, 50.0),
        "1,000-2,000": (1, 1, 0.0, 1, 0.0, 100.0, 0.0, 0, math.nan, 0.0),
        "2,000-5,000": (0, 0, math.nan, 1, 0.0, 0.0, math.nan, 0, math.nan, math.nan),
        ">= 5,000": (1, 1, 1.0, 1, 0.0, 0.0, 0.0, 1, 0.0, 100.0),
        ALL: (4, 3, 4 / 12, 6, 100 / 6, 200 / 6, 25.0, 2, 50.0, 50.0),  # 0.9 beats 0.6 and 0.2; 0.4, 0.3 beat 0.2
    }
    for band, values in expected.items():
        np.testing.assert_allclose(table.loc[band].to_numpy(float), values, err_msg=band)
    assert size_table(scored, vis, SIGMA).localisation_pct.isna().all()  # no hits given: no localisation column


def test_the_all_row_is_the_pooled_metrics():
    scored, vis = scored_and_visibility()
    pooled = detection_metrics(frame_arrays(scored), SIGMA)
    row = size_table(scored, vis, SIGMA).loc[ALL]
    for key in ("auroc_same", "tm_pct", "cm_pct", "target_recall", "first_match_precision"):
        assert row[key] == pytest.approx(pooled[key]), key


def test_best_point_is_the_highest_scoring_one():
    mask = np.zeros((20, 10), np.uint16)
    mask[5:10, 2:6] = 7  # the target
    mask[12:15, 2:6] = 3  # a look-alike
    vis = pd.DataFrame(dict(frame_id=["on", "off", "none", "other_only"], role=["target", "target", "target", "other"],
                            mask_value=[7, 7, 7, 3], pixels=[20, 20, 20, 12]))
    frames = pd.DataFrame(dict(
        frame_id=["on", "off", "none", "other_only"],
        points_x=[[3.5, 8.0], [3.5, 3.0], [], [3.0]], points_y=[[6.2, 1.0], [6.0, 13.0], [], [6.0]],
        point_scores=[[0.9, 0.2], [0.4, 0.8], [], [0.9]]))
    hits = best_point_hits(frames, vis, {"on": mask, "off": mask, "none": mask}.__getitem__)
    assert hits.to_dict("list") == {"frame_id": ["on", "off", "none"], "has_point": [True, True, False],
                                    "hit": [True, False, False]}


def test_paired_bands_point_values_and_a_matcher_against_itself():
    scored, vis = scored_and_visibility()
    perfect = {f: float(objects.get("target") is not None) for f, objects in
               ((f"{e}_{s}", o) for (e, s), (_, o) in FRAMES.items())}
    better, _ = scored_and_visibility(perfect)
    rows = paired_size_rows(scored, better, vis, names=("a", "b"), boot=Bootstrap(n_boot=50))
    assert list(rows.index) == [f"AUROC-same {b} px" for b in BANDS]
    np.testing.assert_allclose(rows["a"], size_table(scored, vis, SIGMA).auroc_same.loc[list(BANDS)])
    np.testing.assert_allclose(rows["b"], [1.0, 1.0, math.nan, 1.0])
    np.testing.assert_allclose(rows["b - a"], [1.0, 1.0, math.nan, 0.0])
    same = paired_size_rows(scored, scored, vis, names=("a", "a2"), boot=Bootstrap(n_boot=50))
    defined = same.dropna(subset=["a"])
    assert (defined["a2 - a"] == 0).all() and (defined["CI low"] == 0).all() and (defined["CI high"] == 0).all()


def test_sizes_section_reads_the_file(tmp_path):
    scored, vis = scored_and_visibility()
    path = tmp_path / "sizes.csv"
    assert sizes_section(path) == []
    path.write_text(size_table(scored, vis, SIGMA, hits_table()).assign(sigma=SIGMA, sigma_source="given").to_csv())
    page = "".join(sizes_section(path))
    assert "&lt; 1,000" in page and "&gt;= 5,000" in page and "sigma 0.5 (given)" in page
    assert "best point on target %" in page and "n/a" in page  # the undefined shares are shown as such
    assert readable(pd.read_csv(path, index_col="band")).loc["< 1,000", "AUROC-same"] == 0.0


# ---------------------------------------------------------------- the files report and compare write
def tiny_table(fs, scores: list[float]) -> ScoreTable:
    """Every frame of the tiny set (val: target, look-alike, other, nothing) with its score and one point at the
    centre of the disc every object is drawn as."""
    rows = [dict(frame_id=f, episode_id=e, step=s, split=sp, score=score, crop_scores=[score], points_x=[148.0],
                 points_y=[348.0], point_scores=[score], view=-1)
            for (f, e, s, sp), score in zip(fs.frames[["frame_id", "episode_id", "step", "split"]].itertuples(
                index=False), scores * 2)]
    meta = dict(matcher="stub", matcher_id=f"stub@{scores[0]}", config_hash="abc", config={},
                frameset_fingerprint=fs.fingerprint, default_sigma=SIGMA, modality="visual")
    return ScoreTable(pd.DataFrame(rows), meta)


def test_report_writes_sizes_beside_its_metrics(tiny_frameset, tmp_path):
    from pin_match.evaluation.flows.report import report

    result = report(tiny_table(tiny_frameset, [0.7, 0.6, 0.2, 0.1]), EvalContext(tiny_frameset, Bootstrap(n_boot=20)),
                    tmp_path, sigma=SIGMA, split="val")
    sizes = pd.read_csv(result["files"]["sizes"], index_col="band")
    assert sizes.loc["2,000-5,000", ["n_target", "n_same", "auroc_same", "localisation_pct"]].tolist() == [
        1, 1, 1.0, 100.0]  # every disc covers about 4,600 px; the point lies on the target
    assert sizes.loc[ALL, "tm_pct"] == pytest.approx(result["metrics"]["tm_pct"])
    assert set(sizes.sigma) == {SIGMA}
    assert "## By the objects' size (pixels)" in (tmp_path / "metrics.md").read_text()


def test_compare_adds_auroc_same_per_band(tiny_frameset, tmp_path):
    from pin_match.evaluation.core.sigma import SigmaChoice
    from pin_match.evaluation.flows.compare import AtSigma, compare

    given = SigmaChoice(SIGMA, "given", "test")
    sides = [AtSigma(tiny_table(tiny_frameset, s), given) for s in ([0.7, 0.6, 0.2, 0.1], [0.4, 0.6, 0.2, 0.1])]
    comparison = compare(*sides, EvalContext(tiny_frameset, Bootstrap(n_boot=20)), tmp_path)
    row = comparison.paired.loc["AUROC-same 2,000-5,000 px"]
    assert row.iloc[:3].tolist() == [1.0, 0.0, -1.0]
    assert comparison.paired.attrs["n_boot"] == 20 and "AUROC-same" in comparison.paired.index
    assert "AUROC-same 2,000-5,000 px" in (tmp_path / "compare.csv").read_text()
