"""Patch-similarity matchers: exact algorithm checks with a stub backbone, and real loading of tiny checkpoints."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_weights import TINY_CLIP, save_tiny_open_clip, save_tiny_timm_vit

from pin_match import Modality, Target, create_matcher
from pin_match.contract.registry import get_matcher_class
from pin_match.contract.weights import WeightsError
from pin_match.evaluation.core.sigma import PAPER_THRESHOLDS
from pin_match.matchers.clip import ClipMatcher, ClipTextMatcher
from pin_match.matchers.common.backbones import PatchFeatures
from pin_match.matchers.common.patch import alpha_to_grid, patch_centres
from pin_match.matchers.dino import DinoMatcher, Dinov2Matcher
from pin_match.nn.prototypes import patch_scores

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("dino", "dinov2", "clip", "clip-text")


# ------------------------------------------------------------------------------ stub backbone


class QuadrantBackbone:
    """grid 2: the token of a patch is the mean RGB of that quadrant of the image, so tests set features by painting."""

    input_size = 2
    grid = 2

    def __init__(self) -> None:
        self.prompts: list[str] = []

    def encode(self, images):
        tokens = []
        for im in images:
            h, w = im.shape[0] // 2, im.shape[1] // 2
            quads = [im[:h, :w], im[:h, w:], im[h:, :w], im[h:, w:]]
            tokens.append([q[..., :3].reshape(-1, 3).astype(np.float64).mean(0) for q in quads])
        patches = torch.tensor(np.array(tokens), dtype=torch.float32)
        return PatchFeatures(cls=patches.mean(1), patches=patches)

    def encode_text(self, texts):
        """Description j (recognised by its marker word) -> axis j, scaled by the prompt length."""
        self.prompts.extend(texts)
        out = torch.zeros(len(texts), 3)
        for i, t in enumerate(texts):
            j = next(k for k, word in enumerate(("alpha", "bravo", "charlie")) if word in t)
            out[i, j] = 1.0 + len(t)
        return out


def quadrant_view(colors, alphas, size=40) -> np.ndarray:
    """An RGBA reference whose four quadrants (TL, TR, BL, BR) have uniform colour and alpha."""
    view = np.zeros((size, size, 4), np.uint8)
    h = size // 2
    for (y, x), c, a in zip(((0, 0), (0, h), (h, 0), (h, h)), colors, alphas):
        view[y:y + h, x:x + h, :3] = c
        view[y:y + h, x:x + h, 3] = a
    return view


VIEW_SPECS = [  # per view: quadrant colours, quadrant alphas
    ([(200, 0, 0), (0, 200, 0), (0, 0, 200), (100, 100, 0)], [255, 0, 255, 51]),
    ([(10, 250, 10), (0, 0, 0), (0, 0, 0), (0, 0, 0)], [255, 0, 0, 0]),
    ([(0, 0, 0), (30, 60, 90), (90, 60, 30), (0, 0, 0)], [0, 102, 102, 0]),
]
# by hand: sum(alpha x colour) / sum(alpha), alpha in [0, 1]
PROTOTYPES = np.array([
    [(200 + 0.2 * 100) / 2.2, (0.2 * 100) / 2.2, 200 / 2.2],
    [10, 250, 10],
    [60, 60, 60],
])

# a 640x360 frame in bands that keep every quadrant of both PIN crops uniform:
# crop 0 (rows 0-360) quadrants = rows 0-180 / 180-360, crop 1 (rows 280-640) = rows 280-460 / 460-640
BANDS = {(0, 180): ((220, 120, 20), (5, 5, 200)), (180, 460): ((1, 1, 60), (200, 10, 10)),
         (460, 640): ((20, 240, 20), (120, 60, 0))}


def banded_frame() -> np.ndarray:
    frame = np.zeros((640, 360, 3), np.uint8)
    for (y0, y1), (left, right) in BANDS.items():
        frame[y0:y1, :180] = left
        frame[y0:y1, 180:] = right
    return frame


def cosine_max(tokens: np.ndarray, targets: np.ndarray) -> np.ndarray:
    t = tokens / np.linalg.norm(tokens, axis=1, keepdims=True)
    p = targets / np.linalg.norm(targets, axis=1, keepdims=True)
    return (t @ p.T).max(axis=1)


def target(views=None, descriptions=("one alpha thing", "a bravo item", "charlie object")) -> Target:
    views = views or tuple(quadrant_view(c, a) for c, a in VIEW_SPECS)
    return Target("obj", "zebracategory", tuple(views), tuple(descriptions))


# ------------------------------------------------------------------------------ algorithm, exact


def test_alpha_resized_bilinearly_to_the_grid():
    view = quadrant_view(VIEW_SPECS[0][0], VIEW_SPECS[0][1])
    np.testing.assert_allclose(alpha_to_grid(view[..., 3], 2).numpy(), [[1, 0], [1, 0.2]], atol=1e-6)


def test_alpha_of_an_object_smaller_than_the_bilinear_samples_still_gives_weight():
    alpha = np.zeros((40, 40), np.uint8)
    alpha[0, 0] = 255
    weights = alpha_to_grid(alpha, 2).numpy()
    np.testing.assert_allclose(weights, [[1 / 400, 0], [0, 0]], atol=1e-7)


def test_reference_prototypes_are_mask_weighted_means():
    m = DinoMatcher(backbone=QuadrantBackbone())
    m.prepare(target())
    np.testing.assert_allclose(m.targets.numpy(), PROTOTYPES, rtol=1e-5)


def test_scores_points_and_frame_mapping_for_the_two_pin_crops():
    m = DinoMatcher(backbone=QuadrantBackbone())
    m.prepare(target())
    r = m.match(banded_frame())

    (a, b), (c, d), (e, f) = BANDS.values()
    crop_tokens = [np.array([a, b, c, d], float), np.array([c, d, e, f], float)]
    expected = [cosine_max(t, PROTOTYPES) for t in crop_tokens]
    np.testing.assert_allclose(r.point_scores, np.concatenate(expected), rtol=1e-5)
    np.testing.assert_allclose(r.crop_scores, [s.max() for s in expected], rtol=1e-5)
    assert r.score == pytest.approx(max(s.max() for s in expected), rel=1e-5)
    # (20, 240, 20) in crop 1's bottom-left is nearly parallel to view 1's prototype
    assert r.score == pytest.approx(cosine_max(np.array([[20, 240, 20.0]]), PROTOTYPES[1:2])[0], rel=1e-5)
    np.testing.assert_allclose(r.heatmap, np.stack(expected).reshape(2, 2, 2), rtol=1e-5)
    # patch centres round((i + 0.5) x 180) in each 360x360 crop, crop 1 shifted down by 280 rows
    np.testing.assert_array_equal(r.points, [[90, 90], [270, 90], [90, 270], [270, 270],
                                             [90, 370], [270, 370], [90, 550], [270, 550]])


def test_max_over_references_takes_the_closest_view():
    m = DinoMatcher(backbone=QuadrantBackbone())
    m.prepare(target())
    r = m.match(banded_frame())
    per_view = [cosine_max(np.array([[20, 240, 20.0]]), PROTOTYPES[k:k + 1])[0] for k in range(3)]
    assert np.argmax(per_view) == 1
    assert r.point_scores[6] == pytest.approx(max(per_view), rel=1e-5)


def test_several_targets_score_as_each_alone():
    """Training scores every query object in one call (Q, V, D); the matcher one target (V, D): the same numbers."""
    torch.manual_seed(0)
    patches, targets = torch.randn(3, 5, 8), torch.randn(2, 4, 8)
    together = patch_scores(patches, targets)
    assert together.shape == (3, 5, 2)
    for q in range(2):
        assert torch.equal(together[..., q], patch_scores(patches, targets[q]))
    cosines = torch.nn.functional.cosine_similarity(patches[:, :, None], targets[1][None, None], dim=-1)
    torch.testing.assert_close(together[..., 1], cosines.amax(-1))


def test_points_at_sigma_keeps_the_patches_above_it():
    m = DinoMatcher(backbone=QuadrantBackbone())
    m.prepare(target())
    r = m.match(banded_frame())
    sigma = float(np.sort(r.point_scores)[-3])
    np.testing.assert_array_equal(r.points_at(sigma), r.points[r.point_scores >= sigma])
    assert len(r.points_at(sigma)) >= 3
    assert len(r.points_at(r.score + 1e-3)) == 0


@pytest.mark.parametrize("grid, width, height", [(3, 100, 50), (4, 100, 100), (37, 360, 360), (14, 333, 517)])
def test_patch_centres_follow_the_rounding_rule(grid, width, height):
    pts = patch_centres(grid, width, height)
    xs = [round((i + 0.5) * width / grid) for i in range(grid)]
    ys = [round((i + 0.5) * height / grid) for i in range(grid)]
    np.testing.assert_array_equal(pts, [[x, y] for y in ys for x in xs])
    assert pts[:, 0].max() < width and pts[:, 1].max() < height


def test_clip_text_uses_the_80_templates_per_description_and_never_the_category():
    stub = QuadrantBackbone()
    m = ClipTextMatcher(backbone=stub)
    m.prepare(target())
    assert len(stub.prompts) == 3 * 80
    for marker in ("alpha", "bravo", "charlie"):
        assert sum(marker in p for p in stub.prompts) == 80
    assert not any("zebracategory" in p for p in stub.prompts)
    # per-template features normalised before averaging: each description is exactly its axis
    np.testing.assert_allclose(m.targets.numpy(), np.eye(3), atol=1e-6)
    r = m.match(banded_frame())
    (a, b), (c, d), (e, f) = BANDS.values()
    tokens = np.array([a, b, c, d, c, d, e, f], float)
    np.testing.assert_allclose(r.point_scores, cosine_max(tokens, np.eye(3)), rtol=1e-5)


def test_embed_reference_is_the_backbone_global_vector():
    m = ClipMatcher(backbone=QuadrantBackbone())
    view = quadrant_view(VIEW_SPECS[0][0], VIEW_SPECS[0][1])
    np.testing.assert_allclose(m.embed_reference(view), [75, 75, 50], rtol=1e-6)


# ------------------------------------------------------------------------------ registry, sigma, no loading


def test_registered_names_modalities_and_paper_sigmas():
    paper = json.loads(PAPER_THRESHOLDS.read_text())["thresholds"]
    for name, cls in zip(NAMES, (DinoMatcher, Dinov2Matcher, ClipMatcher, ClipTextMatcher)):
        assert get_matcher_class(name) is cls
        assert cls.default_sigma == paper[name]["sigma"]
        assert cls.modality is (Modality.TEXTUAL if name == "clip-text" else Modality.VISUAL)
    assert (DinoMatcher.Config().model_name, DinoMatcher.Config().img_size) == ("vit_base_patch16_224.dino", 224)
    assert (Dinov2Matcher.Config().model_name, Dinov2Matcher.Config().img_size) == \
        ("vit_base_patch14_dinov2.lvd142m", 518)
    assert (ClipMatcher.Config().model_name, ClipMatcher.Config().quick_gelu) == ("ViT-B-16", True)


def test_construction_loads_nothing_and_prepare_offline_names_the_hub_id(monkeypatch):
    import open_clip
    import timm

    def forbidden(*args, **kwargs):
        raise AssertionError("a model was built")

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(timm, "create_model", forbidden)
    monkeypatch.setattr(open_clip, "create_model", forbidden)
    for name in NAMES:
        m = create_matcher(name, hub_id="pin-match-test/no-such-model")
        assert m.id.startswith(f"{name}@")
        with pytest.raises(WeightsError, match=r"pin-match-test/no-such-model.*weights="):
            m.prepare(target())
    with pytest.raises(WeightsError, match="does not exist"):
        create_matcher("dino", weights="/nonexistent/pin-match/model.safetensors").prepare(target())


# ------------------------------------------------------------------------------ real loading, tiny checkpoints


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    """Random tiny checkpoints written with the libraries' own savers."""
    from safetensors.torch import load_file

    root = tmp_path_factory.mktemp("patch_ckpt")
    timm_dir = save_tiny_timm_vit(root / "timm")
    clip = save_tiny_open_clip(root / "open_clip")
    return dict(timm_dir=timm_dir, vit=load_file(str(timm_dir / "model.safetensors")), clip_pt=clip["pt"],
                clip_st=clip["safetensors"], clip=clip["state_dict"])


def tiny_config(name: str, ck) -> dict:
    return {
        "dino": dict(model_name="test_vit", img_size=64, weights=str(ck["timm_dir"])),  # a folder
        "dinov2": dict(model_name="test_vit", img_size=48, weights=str(ck["timm_dir"] / "model.safetensors")),
        "clip": dict(model_name=TINY_CLIP, img_size=32, weights=str(ck["clip_pt"])),
        "clip-text": dict(model_name=TINY_CLIP, img_size=32, weights=str(ck["clip_st"])),
    }[name]


def real_target() -> Target:
    rng = np.random.default_rng(1)
    views = []
    for _ in range(3):
        v = np.zeros((96, 72, 4), np.uint8)
        v[..., :3] = rng.integers(0, 256, (96, 72, 3))
        v[20:70, 10:60, 3] = 255
        views.append(v)
    return Target("obj", "mug", tuple(views), ("a red mug", "a mug with yellow stripes", "a ceramic cup"))


@pytest.mark.parametrize("name", NAMES)
def test_tiny_checkpoint_loads_offline_and_matches(name, checkpoints, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    m = create_matcher(name, **tiny_config(name, checkpoints))
    m.prepare(real_target())

    saved = checkpoints["clip"] if name.startswith("clip") else checkpoints["vit"]
    loaded = m.backbone.model.state_dict()
    key = "visual.conv1.weight" if name.startswith("clip") else "patch_embed.proj.weight"
    torch.testing.assert_close(loaded[key], saved[key])

    rng = np.random.default_rng(2)
    frame = rng.integers(0, 256, (640, 360, 3), dtype=np.uint8)
    odd = rng.integers(0, 256, (333, 517, 3), dtype=np.uint8)
    g = m.backbone.grid
    batch = m.match_batch([frame, odd])
    for image, r in zip((frame, odd), batch):
        assert len(r.crop_scores) == 2 and len(r.points) == 2 * g * g
        assert r.heatmap.shape == (2, g, g)
        assert -1 <= r.score <= 1 and r.score == pytest.approx(float(r.point_scores.max()))
        single = m.match(image)
        assert single.score == pytest.approx(r.score, abs=1e-5)
        np.testing.assert_array_equal(single.points, r.points)
        np.testing.assert_allclose(single.point_scores, r.point_scores, atol=1e-5)
    again = m.match(frame)
    np.testing.assert_array_equal(again.point_scores, m.match(frame).point_scores)

    emb = m.embed_reference(real_target().views[0])
    assert emb.ndim == 1 and emb.shape[0] == (16 if name.startswith("clip") else vit_width(checkpoints))
    assert np.isfinite(emb).all()


def vit_width(ck) -> int:
    return ck["vit"]["cls_token"].shape[-1]


def test_clip_patch_tokens_are_in_the_joint_space(checkpoints, monkeypatch):
    """Tokens get ln_post + proj like the CLS does: the projected CLS path reproduces encode_image."""
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    m = create_matcher("clip", **tiny_config("clip", checkpoints))
    image = np.random.default_rng(3).integers(0, 256, (32, 32, 3), dtype=np.uint8)
    feats = m.backbone.encode([image])
    assert feats.patches.shape == (1, 16, 16)  # 4x4 patches, embed_dim 16 (width is 32)
    model = m.backbone.model
    x = torch.from_numpy(image).permute(2, 0, 1)[None].float() / 255
    mean = torch.tensor(m.backbone.mean).view(1, 3, 1, 1)
    std = torch.tensor(m.backbone.std).view(1, 3, 1, 1)
    with torch.inference_mode():
        x = (x - mean) / std
        out = model.visual.forward_intermediates(x, indices=1, normalize_intermediates=True, output_fmt="NLC",
                                                 output_extra_tokens=True)
        cls_projected = out["image_intermediates_prefix"][-1][:, 0] @ model.visual.proj
        torch.testing.assert_close(cls_projected, model.encode_image(x))
        torch.testing.assert_close(feats.patches, out["image_intermediates"][-1] @ model.visual.proj)
