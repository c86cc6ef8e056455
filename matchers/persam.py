"""PerSAM and PerSAM-F: SAM ViT-B features matched to a one-shot target embedding, then SAM's mask.

The score is the best cosine between an observation's SAM encoder features and the target
embedding pooled from a reference under its alpha mask; the points are the pixels of the
mask SAM draws from the most and least similar locations. Compared with Personalize-SAM:
- kept: the target embedding (PerSAM mean; PerSAM-F 0.5 mean + 0.5 channel max), the
  positive (argmax) / negative (argmin) point, PerSAM's target-guided attention and
  target-semantic prompting (transformers' SamModel takes both natively), the two cascaded
  refinements (mask logits as input, then the mask's box), PerSAM-F's two mixing weights of
  the three multimask outputs, learnt on the reference with Dice + focal loss, AdamW, cosine
  schedule;
- changed: three references instead of one (score = max over them; the reference that
  reaches it supplies the embedding, points and PerSAM-F weights); points and similarity
  are picked on SAM's feature grid (inside the unpadded area) instead of the upsampled map;
  a grid cell is inside the reference mask when the object covers at least half of it
  (PerSAM samples the mask bilinearly at the cell centre), or, for an object smaller than
  that, when it is the most covered cell, so the mask never comes out empty; PerSAM-F's
  loss is computed on the decoder's low-resolution logits (the unpadded part) instead of
  full-size ones: SAM is frozen and the prompt fixed, so the decoder runs once and the
  1000 steps cost milliseconds; an empty mask before the box refinement gets the box of
  the positive point's cell instead of failing.
Points carry no own score: every mask pixel is reported when the crop's score passes
sigma, as PIN uses the mask of a detection.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from matchers.hf_load import load_pretrained
from pin_match.frameset import Target
from pin_match.matcher import ConfigError, CropConfig, CropMatcher, MatchResult, Modality, weights_field
from pin_match.registry import register_matcher
from pin_match.weights import WeightsSpec

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
    """Score = max cosine of SAM features to the target embedding; points = SAM's mask from the best point."""

    Config = PerSamConfig
    modality = Modality.VISUAL
    default_sigma = 0.925
    weights_spec = WEIGHTS
    paper = PAPER
    _fine_tunes = False  # PerSAM-F learns mask weights per reference in prepare

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

            self._model = load_pretrained(WEIGHTS, self.cfg.weights, f"matcher {self.display_name}",
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
            cover = self._grid_cover(view[..., 3], feats.shape[-1])
            inside = feats[0][:, cover >= min(0.5, float(cover.max()))]  # (C, n)
            embeddings.append(self._pool(inside))
            if self._fine_tunes:
                mixes.append(self._fit_weights(feats, valid[0], view[..., 3], embeddings[-1]))
        return torch.stack(embeddings), torch.stack(mixes) if self._fine_tunes else None

    @staticmethod
    def _pool(inside: torch.Tensor) -> torch.Tensor:
        return inside.mean(dim=1)

    def _grid_cover(self, alpha: np.ndarray, grid: int) -> torch.Tensor:
        """The fraction of each grid cell the object covers, its alpha mask resized and padded like the image."""
        size = self._model.config.vision_config.image_size
        h, w = alpha.shape
        scale = size / max(h, w)
        a = torch.from_numpy(alpha).float()[None, None] / 255.0
        a = F.interpolate(a, size=(int(h * scale + 0.5), int(w * scale + 0.5)), mode="bilinear", align_corners=False)
        a = F.pad(a, (0, size - a.shape[-1], 0, size - a.shape[-2]))
        return F.adaptive_avg_pool2d(a, (grid, grid))[0, 0]

    def _fit_weights(self, feats: torch.Tensor, valid: tuple[int, int], alpha: np.ndarray,
                     embedding: torch.Tensor) -> torch.Tensor:
        """PerSAM-F training on the reference: positive point at the best location, then fit the mixing."""
        sim = self._similarity(feats, embedding[None])[0, 0]
        pos = self._extreme_points(sim[None], valid_grid=[self._valid_grid(valid, sim.shape[-1])])[0][0]
        with torch.no_grad():
            out = self._model(image_embeddings=feats, input_points=pos[None, None, None].to(feats),
                              input_labels=torch.ones(1, 1, 1, dtype=torch.long, device=feats.device),
                              multimask_output=True)
        logits = out.pred_masks[0, 0]  # (3, h, w) low-resolution
        low = logits.shape[-1]
        target = (self._grid_cover(alpha, low) >= 0.5).float()
        vh, vw = self._valid_grid(valid, low)
        return fit_mask_weights(logits[:, :vh, :vw], target[:vh, :vw], self.cfg.iterations, self.cfg.lr)

    # ------------------------------------------------------------------ shared steps
    def _encode(self, images: list[np.ndarray]) -> tuple[torch.Tensor, list[tuple[int, int]]]:
        """SAM encoder features (B, C, g, g) and each image's unpadded size in model input pixels."""
        inputs = self._processor(images=images, return_tensors="pt")
        with torch.no_grad():
            feats = self._model.get_image_embeddings(inputs["pixel_values"].to(self.cfg.device))
        return feats, [tuple(int(v) for v in s) for s in inputs["reshaped_input_sizes"]]

    def _valid_grid(self, valid: tuple[int, int], grid: int) -> tuple[int, int]:
        size = self._model.config.vision_config.image_size
        return max(1, int(np.ceil(valid[0] * grid / size))), max(1, int(np.ceil(valid[1] * grid / size)))

    @staticmethod
    def _similarity(feats: torch.Tensor, embeddings: torch.Tensor) -> torch.Tensor:
        """Cosine (B, R, g, g) of every location with each of R target embeddings."""
        return torch.einsum("bchw,rc->brhw", F.normalize(feats, dim=1), F.normalize(embeddings, dim=-1))

    def _extreme_points(self, sim: torch.Tensor, valid_grid: list[tuple[int, int]]) -> list[tuple[torch.Tensor, ...]]:
        """Per map (B, g, g): the argmax and argmin locations inside the unpadded area, in model input pixels."""
        cell = self._model.config.vision_config.image_size / sim.shape[-1]
        out = []
        for s, (vh, vw) in zip(sim, valid_grid):
            area = s[:vh, :vw]
            pts = []
            for flat in (area.argmax(), area.argmin()):
                i, j = divmod(int(flat), vw)
                pts.append(torch.tensor([(j + 0.5) * cell, (i + 0.5) * cell]))
            out.append(tuple(pts))
        return out

    def _attention_prior(self, sim: torch.Tensor, valid_grid: list[tuple[int, int]]) -> torch.Tensor:
        """PerSAM's target-guided attention: the standardised similarity through a sigmoid, (B, 1, 1, g*g)."""
        out = []
        for s, (vh, vw) in zip(sim, valid_grid):
            area = s[:vh, :vw]
            out.append(((s - area.mean()) / area.std().clamp_min(1e-6)).sigmoid().flatten())
        return torch.stack(out)[:, None, None]

    def _decode(self, feats: torch.Tensor, points: torch.Tensor, *, multimask: bool, **prompts) -> tuple:
        out = self._model(image_embeddings=feats, input_points=points,
                          input_labels=torch.tensor([[[1, 0]]], device=feats.device).expand(len(feats), 1, 2),
                          multimask_output=multimask, **prompts)
        return out.pred_masks[:, 0], out.iou_scores[:, 0]  # (B, M, h, w), (B, M)

    def _first_mask(self, feats: torch.Tensor, points: torch.Tensor, sim: torch.Tensor, best: torch.Tensor,
                    valid_grid: list[tuple[int, int]]) -> torch.Tensor:
        """PerSAM: one mask with target-guided attention and the target embedding as a semantic prompt."""
        logits, _ = self._decode(feats, points, multimask=False,
                                 attention_similarity=self._attention_prior(sim, valid_grid),
                                 target_embedding=self._embeddings[best][:, None, None])
        return logits[:, 0]

    @staticmethod
    def _pick(logits: torch.Tensor, iou: torch.Tensor) -> torch.Tensor:
        return logits[torch.arange(len(logits)), iou.argmax(dim=1)]

    def _boxes(self, logits: torch.Tensor, points: torch.Tensor, valid: list[tuple[int, int]]) -> torch.Tensor:
        """Bounding boxes (B, 1, 4) of the masks in model input pixels; the positive point's cell when empty."""
        size = self._model.config.vision_config.image_size
        up = F.interpolate(logits[:, None], size=(size, size), mode="bilinear", align_corners=False)[:, 0] > 0
        cell = self._model.config.vision_config.patch_size
        boxes = []
        for m, (vh, vw), p in zip(up, valid, points[:, 0, 0]):
            ys, xs = torch.nonzero(m[:vh, :vw], as_tuple=True)
            if len(xs):
                boxes.append(torch.stack([xs.min(), ys.min(), xs.max(), ys.max()]).float())
            else:
                boxes.append(torch.cat([p - cell / 2, p + cell / 2]))
        return torch.stack(boxes)[:, None]

    # ------------------------------------------------------------------ images
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        feats, valid = self._encode(crops)
        grid = feats.shape[-1]
        valid_grid = [self._valid_grid(v, grid) for v in valid]
        sim_all = self._similarity(feats, self._embeddings)  # (B, R, g, g)
        ref_max = torch.stack([s[:, :vh, :vw].amax(dim=(1, 2)) for s, (vh, vw) in zip(sim_all, valid_grid)])
        best = ref_max.argmax(dim=1)
        sim = sim_all[torch.arange(len(crops)), best]
        points = torch.stack([torch.stack(p) for p in self._extreme_points(sim, valid_grid)])[:, None].to(feats)
        with torch.no_grad():
            logits = self._first_mask(feats, points, sim, best, valid_grid)
            if self.cfg.refine:
                logits = self._pick(*self._decode(feats, points, multimask=True, input_masks=logits[:, None]))
                logits = self._pick(*self._decode(feats, points, multimask=True, input_masks=logits[:, None],
                                                  input_boxes=self._boxes(logits, points, valid)))
        heat = sim_all.amax(dim=1).cpu().numpy()
        return [self._result(crop, lg, v, pt, float(score), hm)
                for crop, lg, v, pt, score, hm in zip(crops, logits, valid, points[:, 0, 0], ref_max.amax(1), heat)]

    def _result(self, crop: np.ndarray, logits: torch.Tensor, valid: tuple[int, int], positive: torch.Tensor,
                score: float, heatmap: np.ndarray) -> MatchResult:
        """The mask at crop resolution, stored as pixels on a stride grid (the positive point when empty)."""
        size = self._model.config.vision_config.image_size
        h, w = crop.shape[:2]
        up = F.interpolate(logits[None, None], size=(size, size), mode="bilinear", align_corners=False)
        up = F.interpolate(up[..., :valid[0], :valid[1]], size=(h, w), mode="bilinear", align_corners=False)[0, 0]
        s = self.cfg.point_stride
        ys, xs = np.arange(s // 2, h, s), np.arange(s // 2, w, s)
        gx, gy = np.meshgrid(xs, ys)
        inside = (up.cpu().numpy() > 0)[gy, gx]
        pts = np.stack([gx[inside], gy[inside]], 1)
        if not len(pts):
            x = min(float(positive[0]) * w / valid[1], w - 1)
            y = min(float(positive[1]) * h / valid[0], h - 1)
            pts = np.array([[x, y]], np.float32)
        return MatchResult(score=score, points=pts, heatmap=heatmap)


@register_matcher("persam-f")
class PerSamFMatcher(PerSamMatcher):
    """PerSAM-F: 0.5 mean + 0.5 max target embedding and learnt mixing of SAM's three masks."""

    Config = PerSamFConfig
    default_sigma = 0.61
    _fine_tunes = True

    @staticmethod
    def _pool(inside: torch.Tensor) -> torch.Tensor:
        return 0.5 * inside.mean(dim=1) + 0.5 * inside.amax(dim=1)

    def _first_mask(self, feats: torch.Tensor, points: torch.Tensor, sim: torch.Tensor, best: torch.Tensor,
                    valid_grid: list[tuple[int, int]]) -> torch.Tensor:
        """PerSAM-F: the three multimask logits mixed with the best reference's learnt weights."""
        logits, _ = self._decode(feats, points, multimask=True)
        return (self._mix[best][:, :, None, None] * logits).sum(dim=1)


def _load_sammodel(source: str):
    """The eval-mode model from a hub id or a save_pretrained folder (through ``load_pretrained``)."""
    from transformers import SamModel

    return SamModel.from_pretrained(source).eval()
