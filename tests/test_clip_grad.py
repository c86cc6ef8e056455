"""CLIP-Grad: the relevance rule by hand, the gradient by analysis, the matcher on a tiny random CLIP."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from tiny_weights import save_tiny_hf_clip

from conftest import noise_frame, red_mug
from pin_match.contract.crops import crop_boxes
from pin_match.contract.matcher import Modality, Target
from pin_match.contract.registry import create_matcher, get_matcher_class
from pin_match.contract.weights import WeightsError
from pin_match.matchers.clip_grad import WEIGHTS, ClipGradMatcher, relevance


@pytest.fixture(scope="module")
def tiny_clip(tmp_path_factory):
    return save_tiny_hf_clip(tmp_path_factory.mktemp("clip") / "tiny")


@pytest.fixture(scope="module")
def target():
    return red_mug(("a red mug with yellow stripes", "a red cup", "a mug on the floor"))


@pytest.fixture(scope="module")
def matcher(tiny_clip, target):
    m = create_matcher("clip-grad", weights=tiny_clip)
    m.prepare(target)
    return m


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
    pv = matcher._pixels([noise_frame(360, 360)])
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

    crops = [noise_frame(360, 360, seed=1), noise_frame(360, 360, seed=2)]
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
    image = noise_frame(*shape, seed=4)
    first, second = matcher.match(image), matcher.match(image)
    assert first.crop_scores is not None and len(first.crop_scores) == 2
    # the upsampled map never exceeds its 7x7 grid; its best stored point is the score
    assert first.score <= float(first.heatmap.max()) + 1e-6
    assert float(first.point_scores.max()) == pytest.approx(first.score)
    crops = [np.ascontiguousarray(c.take(image)) for c in crop_boxes(*shape)]
    up = F.interpolate(10 * matcher.relevance_maps(crops), size=(224, 224), mode="bilinear", align_corners=False)
    np.testing.assert_allclose(first.crop_scores, up.amax(dim=(1, 2, 3)).numpy(), rtol=1e-5)
    assert (first.point_scores <= first.score + 1e-5).all()
    assert len(first.points) > 0 and (first.points[:, 0] < shape[1]).all() and (first.points[:, 1] < shape[0]).all()
    np.testing.assert_array_equal(first.points, second.points)
    np.testing.assert_array_equal(first.point_scores, second.point_scores)
    assert first.score == second.score


def test_points_follow_sigma_and_stride(tiny_clip, target):
    coarse = create_matcher("clip-grad", weights=tiny_clip, point_stride=40)
    coarse.prepare(target)
    r = coarse.match(noise_frame(360, 360, seed=5))
    # the 224 map's pixels 20, 60, ..., 220 per side, plus its maximum when that is off the grid
    centres = (np.arange(20, 224, 40) + 0.5) * 360 / 224 - 0.5
    on_grid = (np.abs(r.points[:, :, None] - centres).min(axis=-1) < 1e-3).all(axis=1)
    assert on_grid.sum() == 6 * 6 and len(r.points) - on_grid.sum() <= 1
    assert r.score == pytest.approx(float(r.point_scores.max()))
    sigma = float(np.median(r.point_scores))
    kept = r.points_at(sigma)
    assert 0 < len(kept) < len(r.points)
    assert set(map(tuple, kept)) == {tuple(p) for p, s in zip(r.points, r.point_scores) if s >= sigma}
    assert len(r.points_at(r.score + 1)) == 0


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


# ---------------------------------------------------------------------------------------------
# An independent re-implementation of CLIP on Wheels' ClipGrad (src/models/localization/clip_grad.py
# with src/clip/model_explainability.py), written in CoW's layout: OpenAI CLIP's forward pass with
# the attention probabilities of every block kept in the graph, one image and one class per pass,
# gradient of 100 x cosine w.r.t. the last block's probabilities (CoW skips blocks 0..num_layers=10
# of ViT-B/32's 12), R <- R + cam @ R from the identity, CLS row without CLS column, bilinear to
# 224, x 10 (CoW's gradient_scalar). Only the weights come from transformers' CLIPModel.

COW_CLIP_MEAN = (0.48145466, 0.4578275, 0.40821073)  # CoW's src/simulation/constants.py
COW_CLIP_STD = (0.26862954, 0.26130258, 0.27577711)


def _cow_block(w: dict, prefix: str, x: torch.Tensor, heads: int, mask: torch.Tensor | None = None):
    """OpenAI CLIP's ResidualAttentionBlock: x + attn(ln_1(x)); x + mlp(ln_2(x)). Returns (x, attention probs)."""
    def ln(t, name):
        return F.layer_norm(t, t.shape[-1:], w[f"{prefix}.{name}.weight"], w[f"{prefix}.{name}.bias"], eps=1e-5)

    def lin(t, name):
        return F.linear(t, w[f"{prefix}.{name}.weight"], w.get(f"{prefix}.{name}.bias"))

    b, n, d = x.shape
    y = ln(x, "layer_norm1")
    q, k, v = (lin(y, f"self_attn.{p}_proj").reshape(b, n, heads, d // heads).transpose(1, 2) for p in "qkv")
    logits = (q * (d // heads) ** -0.5) @ k.transpose(-1, -2)
    probs = torch.softmax(logits if mask is None else logits + mask, dim=-1)  # CoW's attention_probs_forward_hook
    x = x + lin((probs @ v).transpose(1, 2).reshape(b, n, d), "self_attn.out_proj")
    h = lin(ln(x, "layer_norm2"), "mlp.fc1")
    return x + lin(h * torch.sigmoid(1.702 * h), "mlp.fc2"), probs  # QuickGELU


def _cow_encode_image(w: dict, image: torch.Tensor, heads: int):
    """VisionTransformer.forward: conv1 patches, class token, positions, ln_pre, blocks, ln_post(CLS) @ proj."""
    x = F.conv2d(image, w["vision_model.embeddings.patch_embedding.weight"], stride=32).flatten(2).transpose(1, 2)
    cls = w["vision_model.embeddings.class_embedding"].expand(x.shape[0], 1, -1)
    x = torch.cat([cls, x], dim=1) + w["vision_model.embeddings.position_embedding.weight"]
    x = F.layer_norm(x, x.shape[-1:], w["vision_model.pre_layrnorm.weight"], w["vision_model.pre_layrnorm.bias"])
    layers = 1 + max(int(k.split(".")[3]) for k in w if k.startswith("vision_model.encoder.layers."))
    probs = []
    for i in range(layers):
        x, p = _cow_block(w, f"vision_model.encoder.layers.{i}", x, heads)
        probs.append(p)
    pooled = F.layer_norm(x[:, 0], x.shape[-1:], w["vision_model.post_layernorm.weight"],
                          w["vision_model.post_layernorm.bias"])
    return pooled @ w["visual_projection.weight"].T, probs


def _cow_encode_text(w: dict, ids: torch.Tensor, heads: int) -> torch.Tensor:
    """CLIP.encode_text: tokens + positions, causal blocks, ln_final, the EOT token (highest id) @ text_projection."""
    x = w["text_model.embeddings.token_embedding.weight"][ids] + w["text_model.embeddings.position_embedding.weight"]
    n = ids.shape[1]
    mask = torch.full((n, n), float("-inf")).triu_(1)
    layers = 1 + max(int(k.split(".")[3]) for k in w if k.startswith("text_model.encoder.layers."))
    for i in range(layers):
        x, _ = _cow_block(w, f"text_model.encoder.layers.{i}", x, heads, mask)
    x = F.layer_norm(x, x.shape[-1:], w["text_model.final_layer_norm.weight"], w["text_model.final_layer_norm.bias"])
    return x[torch.arange(x.shape[0]), ids.argmax(dim=-1)] @ w["text_projection.weight"].T


def _cow_zeroshot_weights(w: dict, descriptions, heads: int) -> torch.Tensor:
    """CoW's zeroshot_classifier: per class, every template, each L2-normalised, mean, L2-normalised; [dim, n].

    open_clip's 80 templates are CoW's prompt_templates/imagenet_template.json, same order.
    """
    import open_clip
    from open_clip.zero_shot_metadata import OPENAI_IMAGENET_TEMPLATES

    tokenize = open_clip.get_tokenizer("ViT-B-32")  # OpenAI's BPE, 77 tokens, as CoW's clip.tokenize
    columns = []
    with torch.no_grad():
        for d in descriptions:
            e = _cow_encode_text(w, tokenize([t(d) for t in OPENAI_IMAGENET_TEMPLATES]), heads)
            e = e / e.norm(dim=-1, keepdim=True)
            e = e.mean(dim=0)
            columns.append(e / e.norm())
    return torch.stack(columns, dim=1)


def _cow_input(crop: np.ndarray) -> torch.Tensor:
    """ToTensor, bicubic to 224 (antialiased, on a float tensor: not clamped), CLIP normalisation."""
    x = torch.from_numpy(np.ascontiguousarray(crop)).permute(2, 0, 1)[None].float() / 255.0
    x = F.interpolate(x, size=(224, 224), mode="bicubic", align_corners=False, antialias=True)
    return (x - torch.tensor(COW_CLIP_MEAN).view(1, 3, 1, 1)) / torch.tensor(COW_CLIP_STD).view(1, 3, 1, 1)


def _cow_thresholded_map(w: dict, image: torch.Tensor, text_column: torch.Tensor, heads: int) -> torch.Tensor:
    """ClipGrad.forward + interpret_vit up to (not including) the threshold: 10 x upsampled relevance, 224 x 224."""
    features, probs = _cow_encode_image(w, image, heads)
    features = features / features.norm(dim=-1, keepdim=True)
    logits_per_image = 100.0 * features @ text_column[:, None]
    one_hot = (torch.ones(1, 1) * logits_per_image).sum()
    last = probs[-1]  # the only block after num_layers: relevance from the last block alone
    n = last.shape[-1]
    R = torch.eye(n)[None]
    grad = torch.autograd.grad(one_hot, [last], retain_graph=True)[0].detach()
    cam = (grad * last.detach()).clamp(min=0).mean(dim=1)
    R = R + torch.bmm(cam, R)
    rel = R[:, 0, 1:]
    res = int(rel.shape[-1] ** 0.5)
    rel = F.interpolate(rel.reshape(1, 1, res, res), size=224, mode="bilinear", align_corners=False)
    return 10.0 * rel.reshape(224, 224).detach()


@pytest.fixture(scope="module")
def cow_reference(tiny_clip, target):
    """frame -> (n_crops, n_descriptions, 224, 224) maps CoW thresholds, from the same tiny weights."""
    from transformers import CLIPModel

    model = CLIPModel.from_pretrained(tiny_clip).eval()
    w = {k: v.detach().clone().requires_grad_(v.is_floating_point()) for k, v in model.state_dict().items()}
    heads = model.config.vision_config.num_attention_heads
    text = _cow_zeroshot_weights(w, target.descriptions, model.config.text_config.num_attention_heads)

    cache: dict[bytes, torch.Tensor] = {}

    def maps(image: np.ndarray) -> torch.Tensor:
        key = repr(image.shape).encode() + image.tobytes()
        if key not in cache:  # both tests below look at the same frames
            inputs = [_cow_input(c.take(image)) for c in crop_boxes(*image.shape[:2])]
            cache[key] = torch.stack([torch.stack([_cow_thresholded_map(w, x, text[:, t], heads)
                                                   for t in range(text.shape[1])]) for x in inputs])
        return cache[key]
    return maps


COW_SHAPES = [(640, 360), (301, 517), (150, 420), (97, 97)]


@pytest.mark.parametrize("shape", COW_SHAPES)
def test_score_equals_cow_upsampled_relevance_max(matcher, cow_reference, shape):
    image = noise_frame(*shape, seed=11)
    ref = cow_reference(image)
    result = matcher.match(image)
    assert ref.shape[:2] == (len(crop_boxes(*shape)), 3)
    per_crop = ref.amax(dim=(1, 2, 3)).double().numpy()
    np.testing.assert_allclose(result.crop_scores, per_crop, rtol=1e-5, atol=0)
    assert result.score == pytest.approx(float(per_crop.max()), rel=1e-5, abs=0)
    # the maps are not flat (a constant map would make any max-based comparison vacuous)
    assert float(ref.std()) > 1e-3 * float(ref.abs().max())


@pytest.mark.parametrize("shape", COW_SHAPES)
def test_matched_frames_always_have_points(matcher, cow_reference, shape):
    image = noise_frame(*shape, seed=11)
    ref = cow_reference(image).numpy()
    result = matcher.match(image)
    margin = 1e-4 * result.score  # far above the reference/matcher difference (rtol 1e-5 above)
    sigmas = [*np.quantile(ref, [0.0, 0.25, 0.5, 0.9, 0.999]), result.score - margin, result.score + margin,
              float(ref.max()) * 2]
    outcomes = [(bool((ref >= s).any()), result.score >= s, len(result.points_at(s)) > 0) for s in sigmas]
    assert all(len(set(o)) == 1 for o in outcomes), list(zip(sigmas, outcomes))
    assert {o[0] for o in outcomes} == {True, False}
    # at sigma = the score itself the frame is matched and keeps its argmax point; just above, nothing
    assert float(ref.max()) == pytest.approx(result.score, rel=1e-5)
    assert len(result.points_at(result.score)) > 0
    above = float(np.nextafter(np.float32(result.score), np.float32(np.inf)))
    assert result.score < above and len(result.points_at(above)) == 0
