"""PerSAM / PerSAM-F on a tiny random SAM: pooling, score, prompt points, mask-weight fitting, contract."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from tiny_weights import SAM_PATCH, SAM_SIZE, save_tiny_sam

from conftest import make_view
from matchers.persam import WEIGHTS, PerSamFMatcher, PerSamMatcher, dice_loss, fit_mask_weights, focal_loss
from pin_match.crops import crop_boxes
from pin_match.frameset import Target
from pin_match.registry import create_matcher, get_matcher_class
from pin_match.weights import WeightsError

SIZE, PATCH = SAM_SIZE, SAM_PATCH


@pytest.fixture(scope="module")
def tiny_sam(tmp_path_factory):
    return save_tiny_sam(tmp_path_factory.mktemp("sam") / "tiny")


@pytest.fixture(scope="module")
def target():
    views = (make_view((200, 30, 30), stripe=(255, 255, 0)), make_view((200, 30, 30)), make_view((30, 30, 200)))
    return Target("mug_x", "mug", views, ("d0", "d1", "d2"))


@pytest.fixture(scope="module", params=["persam", "persam-f"])
def matcher(request, tiny_sam, target):
    m = create_matcher(request.param, weights=tiny_sam, **({"iterations": 5} if request.param == "persam-f" else {}))
    m.prepare(target)
    return m


def frame(height: int, width: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def independent_similarity(m: PerSamMatcher, crop: np.ndarray) -> torch.Tensor:
    """Cosine (R, valid_h, valid_w) from SAM's own processor and encoder, unpadded area only."""
    from transformers import SamImageProcessor

    inputs = SamImageProcessor(size={"longest_edge": SIZE}, pad_size={"height": SIZE, "width": SIZE})(
        images=[crop], return_tensors="pt")
    feats = m._model.get_image_embeddings(inputs["pixel_values"])[0]
    h, w = (math.ceil(int(v) / PATCH) for v in inputs["reshaped_input_sizes"][0])
    cos = torch.einsum("chw,rc->rhw", F.normalize(feats, dim=0), F.normalize(m._embeddings, dim=-1))
    return cos[:, :h, :w]


def test_target_embedding_pooling():
    inside = torch.tensor([[1., 3., 5.], [-2., 0., 2.]])  # C=2 channels, 3 masked locations
    torch.testing.assert_close(PerSamMatcher._pool(inside), torch.tensor([3., 0.]))
    torch.testing.assert_close(PerSamFMatcher._pool(inside), torch.tensor([0.5 * 3 + 0.5 * 5, 0.5 * 0 + 0.5 * 2]))


def test_reference_mask_reaches_the_feature_grid(tiny_sam, target):
    m = create_matcher("persam", weights=tiny_sam)
    m.prepare(target)
    alpha = np.zeros((100, 200), np.uint8)
    alpha[:, :25] = 255  # a landscape view: resized to 128x256, padded below, so grid rows >= 8 are padding
    cover = m._grid_cover(alpha, 16)  # the object spans 32 input pixels: grid columns 0 and 1
    torch.testing.assert_close(cover[:8, 0], torch.ones(8))
    assert cover[:8, 1].min() > 0.9 and cover[8:].max() == 0 and cover[:, 3:].max() == 0


def test_losses_equal_hand_values():
    logits, target = torch.zeros(1, 2), torch.tensor([[1., 0.]])
    assert float(dice_loss(logits, target)) == pytest.approx(1 - 2 / 3)
    assert float(focal_loss(logits, target)) == pytest.approx(math.log(2) * 0.25 * (0.25 + 0.75) / 2)


def test_mask_weights_move_toward_the_matching_mask():
    target = torch.zeros(8, 8)
    target[2:6, 2:6] = 1
    good = torch.where(target > 0, 6.0, -6.0)
    logits = torch.stack([-good, good, torch.full((8, 8), 3.0)])
    untouched = fit_mask_weights(logits, target, iterations=0, lr=1e-3)
    torch.testing.assert_close(untouched, torch.tensor([1 / 3, 1 / 3, 1 / 3]))
    fitted = fit_mask_weights(logits, target, iterations=200, lr=1e-2)
    assert float(fitted.sum()) == pytest.approx(1.0)
    assert fitted[1] > 1 / 3 + 0.1 and fitted[0] < 1 / 3

    def loss(w):
        mixed = (w[:, None, None] * logits).sum(0)[None]
        return float(dice_loss(mixed, target[None]) + focal_loss(mixed, target[None]))

    assert loss(fitted) < loss(untouched)


def test_persam_f_learns_one_weight_triple_per_reference(tiny_sam, target):
    m = create_matcher("persam-f", weights=tiny_sam, iterations=3)
    m.prepare(target)
    assert m._mix.shape == (3, 3)
    torch.testing.assert_close(m._mix.sum(1), torch.ones(3))
    assert create_matcher("persam", weights=tiny_sam).cfg.__class__.__name__ == "PerSamConfig"


def test_registered_with_paper_settings():
    persam, persam_f = get_matcher_class("persam"), get_matcher_class("persam-f")
    assert persam is PerSamMatcher and persam_f is PerSamFMatcher
    assert (persam.default_sigma, persam_f.default_sigma) == (0.925, 0.61)
    cfg = persam_f.Config()
    assert (cfg.iterations, cfg.lr) == (1000, 1e-3) and persam.weights_spec.hub_id == "facebook/sam-vit-base"


@pytest.mark.parametrize("shape", [(640, 360), (301, 517)])
def test_score_is_max_cosine_and_results_valid(matcher, shape):
    image = frame(*shape, seed=2)
    first, second = matcher.match(image), matcher.match(image)
    crops = [np.ascontiguousarray(c.take(image)) for c in crop_boxes(*shape)]
    expected = [float(independent_similarity(matcher, c).max()) for c in crops]
    np.testing.assert_allclose(first.crop_scores, expected, rtol=1e-5, atol=1e-6)
    assert len(first.points) > 0
    assert (first.points[:, 0] < shape[1]).all() and (first.points[:, 1] < shape[0]).all()
    np.testing.assert_array_equal(first.points, second.points)
    assert first.score == second.score
    best = int(np.argmax(first.crop_scores))
    assert len(first.points_at(first.score)) == int((first.scores_of_points() == first.crop_scores[best]).sum())


def test_whole_frame_ignores_the_padding(tiny_sam, target):
    m = create_matcher("persam", weights=tiny_sam, crops="whole")
    m.prepare(target)
    image = frame(301, 517, seed=3)
    r = m.match(image)
    assert r.score == pytest.approx(float(independent_similarity(m, image).max()), abs=1e-6)


def test_prompt_points_are_best_and_worst_locations(matcher, monkeypatch):
    crop = frame(360, 360, seed=4)
    seen = []
    original = matcher._decode
    monkeypatch.setattr(matcher, "_decode", lambda feats, points, **kw: seen.append(points) or original(
        feats, points, **kw))
    matcher.match(crop)
    sim = independent_similarity(matcher, crop)
    best = sim[int(sim.amax(dim=(1, 2)).argmax())]
    expected = []
    for flat in (best.argmax(), best.argmin()):
        i, j = divmod(int(flat), best.shape[1])
        expected.append([(j + 0.5) * PATCH, (i + 0.5) * PATCH])
    torch.testing.assert_close(seen[0][0, 0], torch.tensor(expected))
    assert len(seen) == 3  # first mask, then PerSAM's two cascaded refinements


def test_offline_without_weights_names_the_hub_id(target):
    if WEIGHTS.available():
        pytest.skip("the hub weights are cached on this machine")
    with pytest.raises(WeightsError, match="facebook/sam-vit-base"):
        PerSamMatcher().prepare(target)


def test_prepare_is_cached_per_target(tiny_sam, target, monkeypatch):
    m = create_matcher("persam-f", weights=tiny_sam, iterations=2)
    m.prepare(target)
    first = m._embeddings
    calls = []
    original = m._target_state
    monkeypatch.setattr(m, "_target_state", lambda t: calls.append(t) or original(t))
    m.prepare(target)
    assert calls == [] and m._embeddings is first
    other = Target("ball_y", "ball", tuple(make_view((30, 200, 30)) for _ in range(3)), ("a", "b", "c"))
    m.prepare(other)
    assert len(calls) == 1 and not torch.equal(m._embeddings, first)
