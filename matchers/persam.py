"""PerSAM and PerSAM-F: SAM ViT-B features matched to a one-shot target embedding, then SAM's mask.

The steps follow Personalize-SAM's ``persam.py`` / ``persam_f.py`` on transformers' SamModel:
- target embedding: the reference's SAM features at the grid cells where its mask, put
  through SAM's own preprocessing (resized, normalised like the image, zero-padded) and
  sampled bilinearly at the cell centres, is above 0; PerSAM averages them, PerSAM-F takes
  0.5 x mean + 0.5 x channel max;
- similarity map: cosine of each cell with the target, upsampled x4 and then like SAM's
  masks (to the padded input, unpadded, to the image), so it is at image resolution;
  the score is its maximum and the positive point its argmax (PerSAM: the negative point
  its argmin), so the point prompts and the score come from one map;
- PerSAM: target-guided attention (the standardised map, resized to the grid, sigmoid)
  and target-semantic prompting in the first decoding, then refinement 1 (mask logits as
  input, three masks, best predicted IoU) and refinement 2 (plus the mask's box);
- PerSAM-F: at test time the positive point only; the three multimask logits mixed with
  the learnt weights, the box of that mixed mask and its logits feed refinement 1, then
  refinement 2 as in PerSAM. The two weights are learnt on the reference at its own
  resolution (Dice + focal loss, AdamW lr 1e-3, eps 1e-4, cosine schedule, 1000 steps).
Changed for PIN: three references instead of one (score = max over them; the reference
that reaches it supplies the embedding, points and PerSAM-F weights); the reference mask
is the alpha channel (> 0); a mask with no cell above 0 (an object smaller than a cell)
keeps its best cell, and an empty mask before a box refinement gets the box of the
positive point's cell, where Personalize-SAM would fail.
Points carry no own score: every pixel of the final mask (on a stride grid; the positive
point when the mask is empty) is reported when the crop's score passes sigma, as PIN uses
the mask of a detection.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from pin_match.contract import (
    ConfigError,
    CropConfig,
    CropMatcher,
    MatchResult,
    Modality,
    Target,
    WeightsSpec,
    register_matcher,
    weights_field,
)

WEIGHTS = WeightsSpec("facebook/sam-vit-base", license="Apache-2.0")
PAPER = "Personalize Segment Anything Model with One Shot (Zhang et al., ICLR 2024)"


@dataclass
class PerSamConfig(CropConfig):
    weights: str | None = weights_field()
    point_stride: int = field(default=8, metadata={"help": "crop pixels between stored mask points"})
    refine: bool = field(default=True, metadata={"help": "PerSAM's two cascaded mask refinements"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.point_stride < 1:
            raise ConfigError(f"persam: point_stride must be >= 1, got {self.point_stride}")


@dataclass
class PerSamFConfig(PerSamConfig):
    iterations: int = field(default=1000, metadata={"help": "fine-tuning steps of the mask weights per reference"})
    lr: float = 1e-3

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.iterations < 0 or self.lr <= 0:
            raise ConfigError(f"persam-f: need iterations >= 0 and lr > 0, got {self.iterations}, {self.lr}")


def dice_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """PerSAM-F's Dice loss (with its +1 smoothing) over flattened masks."""
    prob = logits.sigmoid().flatten(1)
    target = target.flatten(1)
    return (1 - (2 * (prob * target).sum(-1) + 1) / (prob.sum(-1) + target.sum(-1) + 1)).sum()


def focal_loss(logits: torch.Tensor, target: torch.Tensor, alpha: float = 0.25, gamma: float = 2.0) -> torch.Tensor:
    """PerSAM-F's sigmoid focal loss, averaged over pixels."""
    prob = logits.sigmoid()
    ce = F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    p_t = prob * target + (1 - prob) * (1 - target)
    loss = ce * (1 - p_t) ** gamma * (alpha * target + (1 - alpha) * (1 - target))
    return loss.flatten(1).mean(1).sum()


def fit_mask_weights(logits: torch.Tensor, target: torch.Tensor, iterations: int, lr: float) -> torch.Tensor:
    """PerSAM-F's mixing of the 3 multimask logits ``(3, h, w)`` fitted to ``target (h, w)``.

    Two free weights start at 1/3; the first mask gets 1 minus their sum. Returns the 3 weights.
    """
    free = torch.nn.Parameter(torch.full((2,), 1 / 3, device=logits.device))
    optim = torch.optim.AdamW([free], lr=lr, eps=1e-4)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(optim, max(iterations, 1))
    logits, target = logits.detach().flatten(1), target.flatten()[None].float()
    for _ in range(iterations):
        weights = torch.cat([1 - free.sum(0, keepdim=True), free])
        mixed = (weights[:, None] * logits).sum(0, keepdim=True)
        loss = dice_loss(mixed, target) + focal_loss(mixed, target)
        optim.zero_grad()
        loss.backward()
        optim.step()
        sched.step()
    return torch.cat([1 - free.sum(0, keepdim=True), free]).detach()


@register_matcher("persam")
class PerSamMatcher(CropMatcher):
    """Score = max of the upsampled cosine map of SAM features to the target; points = SAM's mask from its argmax."""

    Config = PerSamConfig
    modality = Modality.VISUAL
    default_sigma = 0.925
    weights_spec = WEIGHTS
    paper = PAPER
    version = 2  # what each version changed: docs/baselines.md
    _fine_tunes = False  # PerSAM-F learns mask weights per reference in prepare
    _negative_point = True  # PerSAM prompts the argmin as a negative point; PerSAM-F does not

    def __init__(self, cfg: PerSamConfig | None = None) -> None:
        super().__init__(cfg)
        self._model = None
        self._processor = None
        self._embeddings: torch.Tensor | None = None   # (n_refs, C) target embeddings
        self._mix: torch.Tensor | None = None           # (n_refs, 3) PerSAM-F mask weights; None for PerSAM
        self._cache: dict[str, tuple[torch.Tensor, torch.Tensor | None]] = {}  # views' hash -> the two above

    # ------------------------------------------------------------------ target
    def _prepare(self, target: Target) -> None:
        if self._model is None:
            from transformers import SamImageProcessor

            self._model = self.weights_spec.load_pretrained(self.cfg.weights, f"matcher {self.display_name}",
                                                            _load_sammodel).to(self.cfg.device)
            self._model.requires_grad_(False)
            size = self._model.config.vision_config.image_size
            self._processor = SamImageProcessor(size={"longest_edge": size}, pad_size={"height": size, "width": size})
        key = hashlib.sha1(b"".join(np.ascontiguousarray(v).tobytes() for v in target.views)).hexdigest()
        if key not in self._cache:  # episodes share targets: pool (and fine-tune) each one once
            self._cache[key] = self._target_state(target)
        self._embeddings, self._mix = self._cache[key]

    def _target_state(self, target: Target) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Per reference view: the target embedding and, for PerSAM-F, the fitted mask weights."""
        embeddings, mixes = [], []
        for view in target.views:
            feats, valid = self._encode([np.ascontiguousarray(view[..., :3])])
            cells = self.reference_cells(view[..., 3], feats.shape[-1])
            embeddings.append(self._pool(feats[0][:, cells]))  # (C, n) -> (C,)
            if self._fine_tunes:
                mixes.append(self._fit_weights(feats, valid[0], view[..., 3] > 0, embeddings[-1]))
        return torch.stack(embeddings), torch.stack(mixes) if self._fine_tunes else None

    @staticmethod
    def _pool(inside: torch.Tensor) -> torch.Tensor:
        return inside.mean(dim=1)

    def reference_cells(self, alpha: np.ndarray, grid: int) -> torch.Tensor:
        """The grid cells Personalize-SAM pools: the mask (alpha > 0 as 0 / 255) resized like the image (PIL
        bilinear), normalised with SAM's red-channel mean and std, zero-padded, sampled bilinearly at the cell
        centres, above 0. An object too small for any cell keeps its best one. Returns a (grid, grid) bool."""
        from PIL import Image

        size = self._model.config.vision_config.image_size
        h, w = alpha.shape
        new_h, new_w = self._processor._get_preprocess_shape((h, w), size)
        mask = Image.fromarray(np.where(alpha > 0, 255, 0).astype(np.uint8)).resize((new_w, new_h), Image.BILINEAR)
        mean, std = 255 * self._processor.image_mean[0], 255 * self._processor.image_std[0]
        resized = torch.from_numpy(np.asarray(mask, np.float32))
        m = F.pad((resized - mean) / std, (0, size - new_w, 0, size - new_h))[None, None]
        cells = F.interpolate(m, size=(grid, grid), mode="bilinear", align_corners=False)[0, 0] > 0
        if not cells.any():  # no cell centre on the object: keep the cell it covers most
            cover = F.adaptive_avg_pool2d(F.pad(resized, (0, size - new_w, 0, size - new_h))[None], grid)[0]
            cells = torch.zeros_like(cells).flatten()
            cells[int(cover.argmax())] = True
            cells = cells.reshape(grid, grid)
        return cells

    def _fit_weights(self, feats: torch.Tensor, valid: tuple[int, int], mask: np.ndarray,
                     embedding: torch.Tensor) -> torch.Tensor:
        """PerSAM-F training on the reference at its own resolution: positive point at the best pixel of its own
        similarity map, three masks upsampled to the reference, their mixing fitted to its mask."""
        hw = mask.shape
        sim = self._image_map(self._similarity(feats, embedding[None])[0], valid, hw)[0]
        pos = self._extreme(sim, largest=True)
        logits, _ = self._decode(feats, self._to_input([pos], valid, hw), [1], multimask=True)
        high = self._postprocess(logits, valid, hw)  # (3, H, W)
        target = torch.from_numpy(np.ascontiguousarray(mask)).to(high)
        return fit_mask_weights(high, target, self.cfg.iterations, self.cfg.lr)

    # ------------------------------------------------------------------ shared steps
    def _encode(self, images: list[np.ndarray]) -> tuple[torch.Tensor, list[tuple[int, int]]]:
        """SAM encoder features (B, C, g, g) and each image's unpadded size in model input pixels."""
        inputs = self._processor(images=images, return_tensors="pt")
        with torch.no_grad():
            feats = self._model.get_image_embeddings(inputs["pixel_values"].to(self.cfg.device))
        return feats, [tuple(int(v) for v in s) for s in inputs["reshaped_input_sizes"]]

    @staticmethod
    def _similarity(feats: torch.Tensor, embeddings: torch.Tensor) -> torch.Tensor:
        """Cosine (B, R, g, g) of every location with each of R target embeddings."""
        return torch.einsum("bchw,rc->brhw", F.normalize(feats, dim=1), F.normalize(embeddings, dim=-1))

    def _postprocess(self, maps: torch.Tensor, valid: tuple[int, int], hw: tuple[int, int]) -> torch.Tensor:
        """SAM's mask postprocessing of (N, l, l) maps: to the padded input, unpadded, to the image (N, h, w)."""
        size = self._model.config.vision_config.image_size
        x = F.interpolate(maps[None], size=(size, size), mode="bilinear", align_corners=False)
        return F.interpolate(x[..., :valid[0], :valid[1]], size=hw, mode="bilinear", align_corners=False)[0]

    def _image_map(self, sim: torch.Tensor, valid: tuple[int, int], hw: tuple[int, int]) -> torch.Tensor:
        """Personalize-SAM's similarity map: (R, g, g) upsampled x4, then postprocessed to the image (R, h, w)."""
        return self._postprocess(F.interpolate(sim[None], scale_factor=4, mode="bilinear", align_corners=False)[0],
                                 valid, hw)

    @staticmethod
    def _extreme(sim: torch.Tensor, largest: bool) -> tuple[int, int]:
        """(x, y) of the map's maximum (or minimum), first in row-major order, as ``topk`` picks it."""
        flat = int(sim.flatten().topk(1, largest=largest).indices)
        return flat % sim.shape[1], flat // sim.shape[1]

    @staticmethod
    def _to_input(points: list[tuple[float, float]], valid: tuple[int, int], hw: tuple[int, int]) -> torch.Tensor:
        """Image pixels -> model input pixels, as SAM's ResizeLongestSide.apply_coords: (n, 2)."""
        scale = torch.tensor([valid[1] / hw[1], valid[0] / hw[0]])
        return torch.tensor(points, dtype=torch.float32) * scale

    def _decode(self, feats: torch.Tensor, points: torch.Tensor, labels: list[int], *, multimask: bool,
                **prompts) -> tuple[torch.Tensor, torch.Tensor]:
        """One SAM decoding for one image: mask logits (M, l, l) and predicted IoUs (M,)."""
        with torch.no_grad():
            out = self._model(image_embeddings=feats, input_points=points[None, None].to(feats),
                              input_labels=torch.tensor([[labels]], device=feats.device),
                              multimask_output=multimask, **prompts)
        return out.pred_masks[0, 0], out.iou_scores[0, 0]

    def _box(self, mask: torch.Tensor, positive: tuple[int, int], valid: tuple[int, int]) -> torch.Tensor:
        """The box (1, 1, 4) of an image-resolution mask in model input pixels (the positive point's cell if empty)."""
        ys, xs = torch.nonzero(mask, as_tuple=True)
        hw = mask.shape
        if len(xs):
            corners = [(int(xs.min()), int(ys.min())), (int(xs.max()), int(ys.max()))]
            return self._to_input(corners, valid, hw).reshape(1, 1, 4)
        cell = self._model.config.vision_config.patch_size / 2
        x, y = self._to_input([positive], valid, hw)[0].tolist()
        return torch.tensor([[[x - cell, y - cell, x + cell, y + cell]]])

    def _refine(self, feats: torch.Tensor, points: torch.Tensor, labels: list[int], logits: torch.Tensor,
                box: torch.Tensor | None) -> torch.Tensor:
        """One cascaded refinement: the previous logits as mask input (and a box), three masks, best predicted IoU."""
        extra = {"input_boxes": box.to(feats)} if box is not None else {}
        masks, iou = self._decode(feats, points, labels, multimask=True, input_masks=logits[None, None], **extra)
        return masks[int(iou.argmax())]

    # ------------------------------------------------------------------ images
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        feats, valid = self._encode(crops)
        sims = self._similarity(feats, self._embeddings)  # (B, R, g, g)
        return [self._match_one(crop, feats[i:i + 1], sims[i], valid[i]) for i, crop in enumerate(crops)]

    def _match_one(self, crop: np.ndarray, feats: torch.Tensor, sim: torch.Tensor,
                   valid: tuple[int, int]) -> MatchResult:
        hw = crop.shape[:2]
        maps = self._image_map(sim, valid, hw)  # (R, h, w): the map Personalize-SAM takes its points from
        best = int(maps.flatten(1).amax(1).argmax())
        positive = self._extreme(maps[best], largest=True)
        chosen = [positive, self._extreme(maps[best], largest=False)] if self._negative_point else [positive]
        labels = [1, 0][:len(chosen)]
        points = self._to_input(chosen, valid, hw)
        logits = self._first_mask(feats, points, labels, maps[best], best, valid, hw)
        if self.cfg.refine:
            logits = self._refinements(feats, points, labels, logits, positive, valid, hw)
        return self._result(crop, self._postprocess(logits[None], valid, hw)[0] > 0, positive,
                            float(maps[best][positive[1], positive[0]]), sim.amax(0).cpu().numpy())

    def _first_mask(self, feats: torch.Tensor, points: torch.Tensor, labels: list[int], image_sim: torch.Tensor,
                    best: int, valid: tuple[int, int], hw: tuple[int, int]) -> torch.Tensor:
        """PerSAM: one mask with target-guided attention and the target embedding as a semantic prompt."""
        grid = feats.shape[-1]
        standard = (image_sim - image_sim.mean()) / image_sim.std()
        attention = F.interpolate(standard[None, None], size=(grid, grid), mode="bilinear", align_corners=False)
        logits, _ = self._decode(feats, points, labels, multimask=False,
                                 attention_similarity=attention.sigmoid().flatten(2)[:, None],
                                 target_embedding=self._embeddings[best][None, None, None])
        return logits[0]

    def _refinements(self, feats: torch.Tensor, points: torch.Tensor, labels: list[int], logits: torch.Tensor,
                     positive: tuple[int, int], valid: tuple[int, int], hw: tuple[int, int]) -> torch.Tensor:
        """PerSAM's two cascaded refinements: mask input only, then mask input and the mask's box."""
        logits = self._refine(feats, points, labels, logits, None)
        box = self._box(self._postprocess(logits[None], valid, hw)[0] > 0, positive, valid)
        return self._refine(feats, points, labels, logits, box)

    def _result(self, crop: np.ndarray, mask: torch.Tensor, positive: tuple[int, int], score: float,
                heatmap: np.ndarray) -> MatchResult:
        """The mask's pixels on a stride grid (the positive point when none is inside)."""
        h, w = crop.shape[:2]
        s = self.cfg.point_stride
        gx, gy = np.meshgrid(np.arange(s // 2, w, s), np.arange(s // 2, h, s))
        inside = mask.cpu().numpy()[gy, gx]
        pts = np.stack([gx[inside], gy[inside]], 1)
        if not len(pts):
            pts = np.array([positive], np.float32)
        return MatchResult(score=score, points=pts, heatmap=heatmap)


@register_matcher("persam-f")
class PerSamFMatcher(PerSamMatcher):
    """PerSAM-F: 0.5 mean + 0.5 max target embedding and learnt mixing of SAM's three masks."""

    Config = PerSamFConfig
    default_sigma = 0.61
    _fine_tunes = True
    _negative_point = False

    @staticmethod
    def _pool(inside: torch.Tensor) -> torch.Tensor:
        return 0.5 * inside.mean(dim=1) + 0.5 * inside.amax(dim=1)

    def _first_mask(self, feats: torch.Tensor, points: torch.Tensor, labels: list[int], image_sim: torch.Tensor,
                    best: int, valid: tuple[int, int], hw: tuple[int, int]) -> torch.Tensor:
        """PerSAM-F: the three multimask logits mixed with the best reference's learnt weights (no attention)."""
        logits, _ = self._decode(feats, points, labels, multimask=True)
        return (self._mix[best][:, None, None].to(logits) * logits).sum(dim=0)

    def _refinements(self, feats: torch.Tensor, points: torch.Tensor, labels: list[int], logits: torch.Tensor,
                     positive: tuple[int, int], valid: tuple[int, int], hw: tuple[int, int]) -> torch.Tensor:
        """PerSAM-F's: the mixed mask's box already feeds the first refinement, its box the second."""
        for _ in range(2):
            box = self._box(self._postprocess(logits[None], valid, hw)[0] > 0, positive, valid)
            logits = self._refine(feats, points, labels, logits, box)
        return logits


def _load_sammodel(source: str):
    """The eval-mode model from a hub id or a save_pretrained folder (through ``WeightsSpec.load_pretrained``)."""
    from transformers import SamModel

    return SamModel.from_pretrained(source).eval()
