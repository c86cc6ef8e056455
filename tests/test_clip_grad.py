"""CLIP-Grad: the relevance rule by hand, the gradient by analysis, the matcher on a tiny random CLIP."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from tiny_weights import save_tiny_hf_clip

from conftest import make_view
from matchers.clip_grad import WEIGHTS, ClipGradMatcher, centroid_at, relevance
from pin_match.crops import crop_boxes
from pin_match.frameset import Target
from pin_match.matcher import MatchResult, Modality
from pin_match.registry import create_matcher, get_matcher_class
from pin_match.weights import WeightsError


@pytest.fixture(scope="module")
def tiny_clip(tmp_path_factory):
    return save_tiny_hf_clip(tmp_path_factory.mktemp("clip") / "tiny")


@pytest.fixture(scope="module")
def target():
    views = (make_view((200, 30, 30), stripe=(255, 255, 0)), make_view((200, 30, 30)), make_view((30, 30, 200)))
    return Target("mug_x", "mug", views, ("a red mug with yellow stripes", "a red cup", "a mug on the floor"))


@pytest.fixture(scope="module")
def matcher(tiny_clip, target):
    m = create_matcher("clip-grad", weights=tiny_clip)
    m.prepare(target)
    return m


def frame(height: int, width: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def test_relevance_equals_hand_computation():
    a = torch.tensor([[[.5, .1, .1, .2, .1]] * 5, [[.2, .2, .2, .2, .2]] * 5])       # 2 heads, 5 tokens
    g = torch.tensor([[[1., -2., 3., .5, 0.]] * 5, [[-1., 4., -1., 1., 2.]] * 5])
    # CLS row of I + mean_h clamp(g * a, 0), CLS column dropped:
    # head 0: [.5, -.2, .3, .1, 0] -> [.5, 0, .3, .1, 0]; head 1: [-.2, .8, -.2, .2, .4] -> [0, .8, 0, .2, .4]
    expected = torch.tensor([(0 + .8) / 2, (.3 + 0) / 2, (.1 + .2) / 2, (0 + .4) / 2])
    torch.testing.assert_close(relevance(a, g), expected)
    torch.testing.assert_close(relevance(a[None].repeat(3, 1, 1, 1), g[None].repeat(3, 1, 1, 1)),
                               expected.repeat(3, 1))


def test_relevance_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="relevance"):
        relevance(torch.zeros(2, 5, 5), torch.zeros(2, 4, 4))


def test_autograd_relevance_of_tiny_attention_model_equals_analytic():
    """logit = w . concat_h (A_h V_h)[CLS]: dlogit/dA_h[0, j] = w_h . V_h[j], zero on other rows."""
    gen = torch.Generator().manual_seed(3)
    heads, tokens, dh = 2, 5, 3
    x = torch.randn(tokens, 4, generator=gen)
    wq, wk, wv = (torch.randn(heads, 4, dh, generator=gen) for _ in range(3))
    w = torch.randn(heads, dh, generator=gen)
    q, k, v = (torch.einsum("td,hde->hte", x, m) for m in (wq, wk, wv))
    probs = torch.softmax(q @ k.transpose(-1, -2) / dh ** .5, dim=-1).requires_grad_(True)
    logit = (w * (probs @ v)[:, 0]).sum()
    (grad,) = torch.autograd.grad(logit, probs)

    analytic = torch.zeros(heads, tokens, tokens)
    analytic[:, 0] = torch.einsum("he,hje->hj", w, v)
    torch.testing.assert_close(grad, analytic)
    expected = (probs.detach()[:, 0, 1:] * analytic[:, 0, 1:]).clamp(min=0).mean(0)
    torch.testing.assert_close(relevance(probs.detach(), grad), expected)


def test_rebuilt_last_block_equals_transformers_forward(matcher):
    pv = matcher._pixels([frame(360, 360)])
    vision = matcher._model.vision_model
    with torch.no_grad():
        reference = F.normalize(matcher._model.get_image_features(pixel_values=pv).pooler_output, dim=-1)
        hidden = vision.pre_layrnorm(vision.embeddings(pv))
        for layer in vision.encoder.layers[:-1]:
            hidden = layer(hidden, None)
        rebuilt = matcher._embed_from_probs(hidden, matcher._last_block_probs(hidden))
    torch.testing.assert_close(rebuilt, reference, atol=1e-5, rtol=1e-5)


def test_relevance_maps_equal_gradient_through_eager_attention(tiny_clip, matcher):
    """Independent route: transformers' own eager attention probabilities, gradient by full backprop."""
    from transformers import CLIPModel

    crops = [frame(360, 360, seed=1), frame(360, 360, seed=2)]
    ours = matcher.relevance_maps(crops)
    model = CLIPModel.from_pretrained(tiny_clip, attn_implementation="eager").eval()
    pv = matcher._pixels(crops).requires_grad_(True)
    out = model.vision_model(pixel_values=pv, output_attentions=True)
    image = F.normalize(model.visual_projection(out.pooler_output), dim=-1)
    for t in range(3):
        logit = 100 * (image @ matcher._text[t]).sum()
        (grad,) = torch.autograd.grad(logit, out.attentions[-1], retain_graph=True)
        theirs = relevance(out.attentions[-1].detach(), grad).reshape(2, 7, 7)
        torch.testing.assert_close(ours[:, t], theirs, atol=1e-5, rtol=1e-4)


def test_registered_with_paper_settings():
    cls = get_matcher_class("clip-grad")
    assert cls is ClipGradMatcher and cls.modality is Modality.TEXTUAL and cls.default_sigma == 0.85
    assert cls.weights_spec.hub_id == "openai/clip-vit-base-patch32"


@pytest.mark.parametrize("shape", [(640, 360), (301, 517)])
def test_results_are_valid_and_deterministic(matcher, shape):
    image = frame(*shape, seed=4)
    first, second = matcher.match(image), matcher.match(image)
    assert first.crop_scores is not None and len(first.crop_scores) == 2
    assert first.score == pytest.approx(float(first.heatmap.max()))
    crops = [np.ascontiguousarray(c.take(image)) for c in crop_boxes(*shape)]
    np.testing.assert_allclose(first.crop_scores, 10 * matcher.relevance_maps(crops).amax(dim=(1, 2, 3)).numpy(),
                               rtol=1e-5)
    assert (first.point_scores <= first.score + 1e-5).all()
    assert len(first.points) > 0 and (first.points[:, 0] < shape[1]).all() and (first.points[:, 1] < shape[0]).all()
    np.testing.assert_array_equal(first.points, second.points)
    np.testing.assert_array_equal(first.point_scores, second.point_scores)
    assert first.score == second.score


def test_points_follow_sigma_and_stride(tiny_clip, target):
    coarse = create_matcher("clip-grad", weights=tiny_clip, point_stride=40)
    coarse.prepare(target)
    r = coarse.match(frame(360, 360, seed=5))
    assert len(r.points) == 9 * 9  # 360 / 40 points per side
    sigma = float(np.median(r.point_scores))
    kept = r.points_at(sigma)
    assert 0 < len(kept) < len(r.points)
    assert set(map(tuple, kept)) == {tuple(p) for p, s in zip(r.points, r.point_scores) if s >= sigma}
    assert len(r.points_at(r.score + 1)) == 0


def test_centroid_is_relevance_weighted_and_recomputed_per_sigma():
    r = MatchResult(score=0.9, points=[[0, 0], [10, 0], [10, 10]], point_scores=[0.9, 0.3, 0.6])
    np.testing.assert_allclose(centroid_at(r, 0.5), [[(0 * .9 + 10 * .6) / 1.5, 10 * .6 / 1.5]], rtol=1e-6)
    np.testing.assert_allclose(centroid_at(r, 0.8), [[0, 0]])
    assert centroid_at(r, 0.95).shape == (0, 2)


def test_offline_without_weights_names_the_hub_id(target):
    if WEIGHTS.available():
        pytest.skip("the hub weights are cached on this machine")
    with pytest.raises(WeightsError, match="openai/clip-vit-base-patch32"):
        ClipGradMatcher().prepare(target)


def test_text_targets_are_cached_per_description_set(matcher, target):
    first = matcher._text
    matcher.prepare(target)
    assert matcher._text is first
    matcher.prepare(Target("x", "mug", target.views, ("a green ball", "a ball", "a toy")))
    assert matcher._text.shape == first.shape and not torch.allclose(matcher._text, first)
    matcher.prepare(target)
    assert matcher._text is first
