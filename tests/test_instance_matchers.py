"""effnet-parts, parts-cascade and fusion: the math on hand-set numbers, the contract, ids, and the fusion fit."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from pin_match.contract import ConfigError, MatchResult, WeightsError, check_matcher, create_matcher
from pin_match.matchers.cascade import cascade_result, keypoint_bonus
from pin_match.matchers.common.cell_parts import part_matches, reference_cells
from pin_match.matchers.common.fusion_file import read_fusion
from pin_match.matchers.fusion import fused_score


def unit(*rows):
    return torch.tensor(rows, dtype=torch.float32)


# ------------------------------------------------------------------ effnet-parts

# three reference cells of view 0 (e1, e2, e3) and one of view 1 (.6 e1 + .8 e3); the crop has three cells
REFS = unit([1, 0, 0], [0, 1, 0], [0, 0, 1], [0.6, 0, 0.8])
VIEWS = torch.tensor([0, 0, 0, 1])
# cell 0 = e1, cell 1 = (e1 + e2)/sqrt 2, cell 2 = e2 weakly: cos(e1)=1, cos(e2 with cell1)=.707, cos(e2, cell2)=.6
CELLS = unit([1, 0, 0], [0.7071068, 0.7071068, 0], [0.8, 0.6, 0])


def test_topk_averages_the_best_matches_of_each_view_and_takes_the_best_view():
    # view 0's best matches: e1 -> cell0 (1.0), e2 -> cell1 (.7071), e3 -> none (0.0); view 1's: cell0 (.6)
    score, chosen, chosen_scores = part_matches(REFS, VIEWS, CELLS, "topk", 2 / 3)
    assert score == pytest.approx((1.0 + 0.7071068) / 2, abs=1e-5)  # view 0's top 2 of 3 beat view 1's .6 ...
    score_all, *_ = part_matches(REFS, VIEWS, CELLS, "topk", 1.0)
    assert score_all == pytest.approx(0.6, abs=1e-6)  # ... but with all of its cells, view 0 has .569 < .6
    assert chosen.tolist() == [0, 1]  # the cells chosen by some reference cell, each with the best cosine
    assert chosen_scores.tolist() == pytest.approx([1.0, 0.7071068], abs=1e-5)


def test_mutual_counts_only_matches_that_choose_each_other():
    refs, views = unit([1, 0, 0], [0, 1, 0]), torch.tensor([0, 0])
    cells = unit([1, 0, 0], [0.6, 0.8, 0])  # cell1: cos(e1)=.6 < cos(e2)=.8, so e2 <-> cell1 is mutual
    score, *_ = part_matches(refs, views, cells, "mutual", 1.0)
    assert score == pytest.approx((1.0 + 0.8) / 2, abs=1e-6)
    cells = unit([1, 0, 0], [0.9, 0.4358899, 0])  # e2's best is cell1, but cell1 prefers e1: not mutual
    score, *_ = part_matches(refs, views, cells, "mutual", 1.0)
    assert score == pytest.approx(1.0 / 2, abs=1e-6)


def test_a_frame_matched_at_sigma_always_has_a_point():
    gen = torch.Generator().manual_seed(0)
    for aggregate in ("topk", "mutual"):
        for _ in range(20):
            score, _, chosen_scores = part_matches(torch.randn(12, 8, generator=gen), torch.arange(12) % 3,
                                                   torch.randn(9, 8, generator=gen), aggregate, 0.25)
            assert chosen_scores.max() >= score - 1e-6


def test_reference_cells_keep_the_best_covered_cell_of_a_tiny_mask():
    assert reference_cells(torch.tensor([[0.0, 0.6], [0.5, 0.2]]), 0.5).tolist() == [1, 2]
    assert reference_cells(torch.tensor([[0.0, 0.1], [0.3, 0.2]]), 0.5).tolist() == [2]


def test_parts_config_is_checked_and_hashed():
    with pytest.raises(ConfigError, match="aggregate='max'"):
        create_matcher("effnet-parts", aggregate="max")
    with pytest.raises(ConfigError, match="top_fraction=0"):
        create_matcher("effnet-parts", top_fraction=0)
    base = create_matcher("effnet-parts")
    assert (base.cfg.layer, base.cfg.img_size) == ("head", 448)
    assert create_matcher("effnet-parts", top_fraction=0.5).id != base.id
    assert create_matcher("effnet-parts").id == base.id


def test_parts_contract_with_real_weights():
    scores = check_matcher("effnet-parts", img_size=64)
    assert all(-1.0 <= s <= 1.0 for s in scores.values())
    assert all(-1.0 <= s <= 1.0 for s in check_matcher("effnet-parts", img_size=64, aggregate="mutual").values())


# ------------------------------------------------------------------ parts-cascade

def test_cascade_adds_log_matches_and_keeps_the_score_the_max_of_the_point_map():
    patch = MatchResult(score=0.6, points=[[1, 1], [2, 2]], point_scores=[0.6, 0.4])
    keypoints = MatchResult(score=9.0, points=[[5, 5]])
    out = cascade_result(patch, keypoints, 0.1)
    assert out.score == pytest.approx(0.6 + 0.1 * math.log(10.0))
    assert out.scores_of_points().tolist() == pytest.approx([out.score, 0.4 + 0.1 * math.log(10.0), out.score])
    assert out.points.tolist() == [[1, 1], [2, 2], [5, 5]]
    assert keypoint_bonus(0.0, 0.1) == 0.0
    assert cascade_result(patch, MatchResult(score=0.0), 0.1).score == pytest.approx(0.6)


def test_cascade_config_errors_and_id_covers_the_parts():
    with pytest.raises(ConfigError, match="config key 'patch_cfg': cannot read 'layer'"):
        create_matcher("parts-cascade", patch_cfg="layer")
    with pytest.raises(ConfigError, match="matcher parts-cascade, patch part: .*layer='tail'"):
        create_matcher("parts-cascade", **{"patch_cfg.layer": "tail"})
    with pytest.raises(ConfigError, match="weight=-1"):
        create_matcher("parts-cascade", weight=-1)
    with pytest.raises(ConfigError, match="keypoints part 'owl' is of the textual modality"):
        create_matcher("parts-cascade", keypoints="owl")
    a = create_matcher("parts-cascade", keypoints="sift")
    assert a.parts()["patch"].cfg.img_size == 448
    b = create_matcher("parts-cascade", keypoints="sift", **{"patch_cfg.img_size": "224"})
    assert b.parts()["patch"].cfg.img_size == 224 and b.id != a.id
    assert create_matcher("parts-cascade", keypoints="sift", patch_cfg={"img_size": 224}).id == b.id


def test_cascade_contract():
    scores = check_matcher("parts-cascade", patch_cfg={"img_size": 64}, keypoints="sift")
    assert all(np.isfinite(list(scores.values())))


# ------------------------------------------------------------------ fusion

def fusion_file(path, components, coefs, intercept=0.5):
    spec = dict(format="pin-match-fusion", version=1, intercept=intercept, points_from=0,
                components=[dict(matcher=name, config=cfg, id=create_matcher(name, **cfg).id, transform=t, coef=c)
                            for (name, cfg, t), c in zip(components, coefs)], fitted_on={})
    path.write_text(json.dumps(spec))
    return path


COLOR_SIFT = [("color", {}, "identity"), ("sift", {}, "log1p")]


def test_fused_score_is_the_logit_of_the_file(tmp_path):
    spec = read_fusion(fusion_file(tmp_path / "f.json", COLOR_SIFT, [2.0, 0.5]))
    assert fused_score(spec, [0.25, math.e - 1]) == pytest.approx(0.5 + 2.0 * 0.25 + 0.5 * 1.0)


def test_fusion_contract_and_id_hashes_the_file(tmp_path):
    path = fusion_file(tmp_path / "f.json", COLOR_SIFT, [2.0, 0.5])
    scores = check_matcher("fusion", weights=str(path))
    color = check_matcher("color")
    sift = check_matcher("sift")
    for frame, s in scores.items():
        assert s == pytest.approx(0.5 + 2.0 * color[frame] + 0.5 * math.log1p(sift[frame]), abs=1e-4)
    first = create_matcher("fusion", weights=str(path)).id
    fusion_file(path, COLOR_SIFT, [2.0, 0.25])
    assert create_matcher("fusion", weights=str(path)).id != first


def test_fusion_refuses_bad_files(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    with pytest.raises(WeightsError, match=r"^cannot read fusion file .*bad\.json as JSON: Expecting"):
        create_matcher("fusion", weights=str(bad))
    path = fusion_file(tmp_path / "f.json", COLOR_SIFT, [1.0, 1.0])
    spec = json.loads(path.read_text())
    spec["components"][0]["id"] = "color@000000000000"
    path.write_text(json.dumps(spec))
    with pytest.raises(WeightsError, match="fitted as color@000000000000.*refit the fusion"):
        create_matcher("fusion", weights=str(path))
    spec["components"][0]["transform"] = "sqrt"
    path.write_text(json.dumps(spec))
    with pytest.raises(WeightsError, match="component 0 needs"):
        create_matcher("fusion", weights=str(path))


def test_default_fusion_file_is_valid():
    matcher = create_matcher("fusion")
    assert matcher.spec["fitted_on"]["split"] == "train"
    assert [p.display_name for p in matcher.components][0] == "effnet-parts"


# ------------------------------------------------------------------ fitting

def test_logistic_fit_recovers_a_separating_direction():
    from pin_match.fitting.logistic import logistic_fit

    rng = np.random.default_rng(0)
    x = rng.normal(size=(400, 2))
    y = (x[:, 0] * 3 + 0.2 * rng.normal(size=400) > 0).astype(float)  # only feature 0 matters
    beta = logistic_fit(x, y, np.full(400, 1 / 400), l2=1e-3)
    assert beta[1] > 5 * abs(beta[2]) and beta[1] > 0


def test_fit_fusion_on_cached_tables(tiny_frameset, tmp_path):
    from pin_match.fitting.fusion import fit_fusion

    out = tmp_path / "f.json"
    spec = fit_fusion(tiny_frameset, COLOR_SIFT, out, split="train", out=tmp_path / "scores")
    assert spec["fitted_on"]["split"] == "train" and spec["fitted_on"]["frames"] == 4
    assert spec["fitted_on"]["classes"] == {"target": 1, "same_category": 1, "other": 2}
    assert [c["id"] for c in spec["components"]] == [create_matcher(n).id for n, _, _ in COLOR_SIFT]
    matcher = create_matcher("fusion", weights=str(out))  # the written file is one the matcher takes
    assert matcher.spec == spec
    assert (tmp_path / "scores").is_dir()  # component tables went through the score cache


def test_the_carried_fusion_file_fits_its_components_as_they_are_now():
    """The default fusion file records each component's id; a change that moves one (a new hashed config field,
    a version bump) makes ``fusion`` refuse it, so such a change must refit the file: this says so first."""
    from pin_match.matchers.fusion import FusionMatcher

    recorded = [c["id"] for c in read_fusion(FusionMatcher.weights_spec.resolve(None))["components"]]
    assert [part.id for part in create_matcher("fusion").components] == recorded


def test_the_carried_fusion_file_is_under_the_projects_licence():
    """Issue 43.1: the file was fitted by pin_match, so it comes under pin_match's licence (MIT), not Apache-2.0."""
    from importlib.metadata import metadata

    from pin_match.matchers.fusion import FusionMatcher

    project = metadata("pin-match")["License"]
    assert project == "MIT"
    assert f"({project})" in FusionMatcher.weights_spec.license and "Apache" not in FusionMatcher.weights_spec.license
