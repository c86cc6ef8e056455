"""PerSAM / PerSAM-F on a tiny random SAM: pooling, mask-weight fitting, and the whole matcher against an
independent re-implementation of Personalize-SAM's persam.py / persam_f.py on the same weights."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from tiny_weights import SAM_PATCH, SAM_SIZE, save_tiny_sam

from conftest import make_view, noise_frame, red_mug
from pin_match.contract.matcher import Target
from pin_match.contract.registry import create_matcher, get_matcher_class
from pin_match.contract.weights import WeightsError
from pin_match.matchers.persam import WEIGHTS, PerSamFMatcher, PerSamMatcher, dice_loss, fit_mask_weights, focal_loss

SIZE, PATCH = SAM_SIZE, SAM_PATCH


@pytest.fixture(scope="module")
def tiny_sam(tmp_path_factory):
    return save_tiny_sam(tmp_path_factory.mktemp("sam") / "tiny")


@pytest.fixture(scope="module")
def target():
    return red_mug(("d0", "d1", "d2"))


@pytest.fixture(scope="module", params=["persam", "persam-f"])
def matcher(request, tiny_sam, target):
    m = create_matcher(request.param, weights=tiny_sam, **({"iterations": 5} if request.param == "persam-f" else {}))
    m.prepare(target)
    return m


def sam_processor():
    from transformers import SamImageProcessor, SamProcessor

    return SamProcessor(image_processor=SamImageProcessor(size={"longest_edge": SIZE},
                                                          pad_size={"height": SIZE, "width": SIZE}))


def reference_cells(alpha: np.ndarray) -> torch.Tensor:
    """Personalize-SAM's ``set_image(ref_image, ref_mask)`` then ``F.interpolate(..., bilinear) > 0``, red channel:
    the 0 / 255 mask resized like the image (torchvision on PIL), normalised with SAM's pixel mean and std,
    zero-padded to the square input, sampled at the feature grid."""
    from torchvision.transforms.functional import resize, to_pil_image

    mask = np.repeat(np.where(alpha > 0, 255, 0).astype(np.uint8)[..., None], 3, axis=2)
    h, w = alpha.shape
    scale = SIZE / max(h, w)
    resized = np.array(resize(to_pil_image(mask), [int(h * scale + 0.5), int(w * scale + 0.5)]))
    x = (torch.from_numpy(resized).permute(2, 0, 1).float() - torch.tensor([123.675, 116.28, 103.53])[:, None, None]) \
        / torch.tensor([58.395, 57.12, 57.375])[:, None, None]
    x = F.pad(x, (0, SIZE - x.shape[-1], 0, SIZE - x.shape[-2]))[None]
    return F.interpolate(x, size=(SIZE // PATCH, SIZE // PATCH), mode="bilinear")[0, 0] > 0


def point_selection(sim: torch.Tensor, largest: bool = True) -> list[int]:
    """Personalize-SAM's ``point_selection``: top-1 of the flattened map, returned as (x, y)."""
    flat = int(sim.flatten(0).topk(1, largest=largest)[1])
    row = flat // sim.shape[1]
    return [flat - row * sim.shape[1], row]


class Encoded(NamedTuple):
    """What ``set_image`` leaves for ``predict``: SAM's image embeddings, the processor's sizes, the image."""

    feats: torch.Tensor
    sizes: Any
    image: np.ndarray


class PersonalizeSam:
    """Personalize-SAM's test loop (and PerSAM-F's training) for one reference, on transformers' SamModel, with
    transformers' SamProcessor for the coordinate transforms and the mask postprocessing (its own code, not the
    matcher's)."""

    def __init__(self, model, view: np.ndarray, fine_tune: bool, iterations: int = 0, lr: float = 1e-3):
        self.model, self.proc, self.fine_tune = model, sam_processor(), fine_tune
        ref = self.set_image(view[..., :3])
        target = ref.feats[0].permute(1, 2, 0)[reference_cells(view[..., 3])]  # (n, C)
        embedding = 0.5 * target.max(0).values + 0.5 * target.mean(0) if fine_tune else target.mean(0)
        self.target_embedding = embedding[None, None]
        self.target_feat = F.normalize(embedding[None], dim=-1)
        if fine_tune:
            self.weights = self.train(ref, torch.from_numpy(view[..., 3] > 0).float().flatten()[None], iterations, lr)

    def set_image(self, image) -> Encoded:
        enc = self.proc(images=image, return_tensors="pt")
        with torch.no_grad():
            return Encoded(self.model.get_image_embeddings(enc["pixel_values"]), enc, image)

    def predict(self, img: Encoded, points, labels, box=None, mask_input=None, multimask=True, **extra):
        feats, sizes = img.feats, img.sizes
        enc = self.proc(images=img.image, input_points=[[points]], input_labels=[[labels]],
                        input_boxes=None if box is None else [[box]], return_tensors="pt")
        with torch.no_grad():
            out = self.model(image_embeddings=feats, input_points=enc["input_points"].float(),
                             input_labels=enc["input_labels"], multimask_output=multimask,
                             input_boxes=None if box is None else enc["input_boxes"].float(),
                             input_masks=None if mask_input is None else mask_input[None], **extra)
        high = self.proc.post_process_masks(out.pred_masks, sizes["original_sizes"], sizes["reshaped_input_sizes"],
                                            binarize=False)[0][0]
        return high > 0, out.iou_scores[0, 0], out.pred_masks[0, 0], high

    def similarity(self, img: Encoded):
        feats, sizes = img.feats, img.sizes
        c, h, w = feats[0].shape
        sim = (self.target_feat @ F.normalize(feats[0], dim=0).reshape(c, h * w)).reshape(1, 1, h, w)
        sim = F.interpolate(sim, scale_factor=4, mode="bilinear")
        return self.proc.post_process_masks(sim[None], sizes["original_sizes"], sizes["reshaped_input_sizes"],
                                            binarize=False)[0][0, 0]

    def train(self, ref: Encoded, gt, iterations, lr):
        pos = point_selection(self.similarity(ref))
        _, _, _, high = self.predict(ref, [pos], [1])
        free = torch.nn.Parameter(torch.ones(2, 1) / 3)
        optimizer = torch.optim.AdamW([free], lr=lr, eps=1e-4)
        scheduler = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, iterations)
        for _ in range(iterations):
            weights = torch.cat((1 - free.sum(0).unsqueeze(0), free), dim=0)
            logits = (high.flatten(1) * weights).sum(0).unsqueeze(0)
            prob = logits.sigmoid()
            dice = 1 - (2 * (prob * gt).sum(-1) + 1) / (prob.sum(-1) + gt.sum(-1) + 1)
            ce = F.binary_cross_entropy_with_logits(logits, gt, reduction="none")
            p_t = prob * gt + (1 - prob) * (1 - gt)
            focal = (ce * (1 - p_t) ** 2 * (0.25 * gt + 0.75 * (1 - gt))).mean(1)
            loss = dice.sum() + focal.sum()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            scheduler.step()
        return torch.cat((1 - free.sum(0).unsqueeze(0), free), dim=0).detach()

    @staticmethod
    def box_of(mask):
        y, x = np.nonzero(mask.numpy())
        return [int(x.min()), int(y.min()), int(x.max()), int(y.max())]

    def segment(self, image):
        """(score, positive point, final mask) for one test image."""
        img = self.set_image(image)
        sim = self.similarity(img)
        pos = point_selection(sim)
        if not self.fine_tune:
            points, labels = [pos, point_selection(sim, largest=False)], [1, 0]
            standard = (sim - sim.mean()) / torch.std(sim)
            attn = F.interpolate(standard[None, None], size=img.feats.shape[-2:], mode="bilinear").sigmoid()
            masks, scores, logits, _ = self.predict(img, points, labels, multimask=False,
                                                    attention_similarity=attn.unsqueeze(0).flatten(3),
                                                    target_embedding=self.target_embedding)
            masks, scores, logits, _ = self.predict(img, points, labels, mask_input=logits[0:1])
        else:
            points, labels = [pos], [1]
            _, _, logits, high = self.predict(img, points, labels)
            mask = (high * self.weights[..., None]).sum(0) > 0
            logit = (logits * self.weights[..., None]).sum(0)
            masks, scores, logits, _ = self.predict(img, points, labels, box=self.box_of(mask),
                                                    mask_input=logit[None])
        best = int(scores.argmax())
        masks, scores, logits, _ = self.predict(img, points, labels, box=self.box_of(masks[best]),
                                                mask_input=logits[best:best + 1])
        return float(sim.max()), pos, masks[int(scores.argmax())]


def test_target_embedding_pooling():
    inside = torch.tensor([[1., 3., 5.], [-2., 0., 2.]])  # C=2 channels, 3 masked locations
    torch.testing.assert_close(PerSamMatcher._pool(inside), torch.tensor([3., 0.]))
    torch.testing.assert_close(PerSamFMatcher._pool(inside), torch.tensor([0.5 * 3 + 0.5 * 5, 0.5 * 0 + 0.5 * 2]))


def test_reference_cells_are_the_bilinear_mask_above_zero(tiny_sam, target):
    m = create_matcher("persam", weights=tiny_sam)
    m.prepare(target)
    alpha = np.zeros((100, 200), np.uint8)
    alpha[:, :25] = 255  # a landscape view: resized to 128x256, padded below; the object spans 32 input pixels
    cells = m.reference_cells(alpha, 16)
    expected = torch.zeros(16, 16, dtype=torch.bool)
    expected[:8, :2] = True  # cell centres at input pixels 16 i + 7.5: columns 0, 1 inside, rows 8+ are padding
    torch.testing.assert_close(cells, expected)
    torch.testing.assert_close(cells, reference_cells(alpha))
    alpha = np.zeros((256, 256), np.uint8)
    alpha[0:3, 0:3] = 255  # smaller than a cell and off its centre: the best cell is kept
    assert int(m.reference_cells(alpha, 16).sum()) == 1 and bool(m.reference_cells(alpha, 16)[0, 0])


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
def test_results_are_valid_and_every_matched_frame_has_points(matcher, shape):
    image = noise_frame(*shape, seed=2)
    first, second = matcher.match(image), matcher.match(image)
    assert len(first.points_at(first.score)) > 0  # the best crop's mask (or its positive point) at any sigma
    assert (first.points[:, 0] < shape[1]).all() and (first.points[:, 1] < shape[0]).all()
    np.testing.assert_array_equal(first.points, second.points)
    assert first.score == second.score and first.score == pytest.approx(float(first.crop_scores.max()))


@pytest.mark.parametrize("name,shape", [("persam", (360, 360)), ("persam", (301, 517)), ("persam-f", (360, 360)),
                                        ("persam-f", (301, 517))])
def test_matcher_equals_personalize_sam(tiny_sam, target, name, shape):
    """Score, positive point and final mask of the matcher against Personalize-SAM's own steps for one reference
    view (a target whose three views are that view, so the best reference is that view)."""
    options = {"iterations": 5} if name == "persam-f" else {}
    image = noise_frame(*shape, seed=9)
    for view in (target.views[0] if shape[0] == 360 else target.views[2],):  # both views over the parameters
        m = create_matcher(name, weights=tiny_sam, crops="whole", point_stride=4, **options)
        m.prepare(Target("one", "mug", (view,) * 3, ("a", "b", "c")))
        seen = []

        def spy(feats, points, labels, decode=m._decode, seen=seen, **kw):  # records the prompts on the way
            seen.append((points, labels))
            return decode(feats, points, labels, **kw)

        m._decode = spy
        r = m.match(image)
        ref = PersonalizeSam(m._model, view, fine_tune=name == "persam-f", iterations=5)
        score, positive, mask = ref.segment(image)
        assert r.score == pytest.approx(score, abs=1e-6)  # the map's max at image resolution, not the grid's
        h, w = shape
        expected_point = ref.proc(images=image, input_points=[[[positive]]], return_tensors="pt")["input_points"]
        torch.testing.assert_close(seen[0][0][0], expected_point[0, 0, 0].float())  # in model input pixels
        assert seen[0][1] == ([1, 0] if name == "persam" else [1])  # PerSAM-F: no negative point
        gx, gy = np.meshgrid(np.arange(2, w, 4), np.arange(2, h, 4))
        inside = mask.numpy()[gy, gx]
        expected = np.stack([gx[inside], gy[inside]], 1) if inside.any() else np.array([positive])
        np.testing.assert_array_equal(r.points, expected)
        if name == "persam-f":
            torch.testing.assert_close(m._mix[0], ref.weights[:, 0], atol=1e-5, rtol=0)


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
