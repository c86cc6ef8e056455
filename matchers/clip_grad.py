"""CLIP-Grad: text-conditioned gradient relevance of CLIP ViT-B/32, as CLIP on Wheels uses it.

The score is how strongly the last attention block's CLS row, weighted by the gradient of
the image-text logit, points at any patch (Chefer et al.'s relevance, last block only);
the points are the pixels of that relevance map. As in CoW, the map that is thresholded is
10 x the relevance upsampled bilinearly to the 224 x 224 input; the score is that map's
maximum, so any sigma the score reaches keeps at least one point. We run transformers' CLIPModel but
recompute the last block ourselves, so the post-softmax attention probabilities are a leaf
of the graph and autograd gives their gradient without tracking the rest of the network.
"""

from __future__ import annotations

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

WEIGHTS = WeightsSpec("openai/clip-vit-base-patch32", license="MIT")
RELEVANCE_SCALE = 10.0  # CoW multiplies the relevance by 10 before thresholding
LOGIT_SCALE = 100.0     # the logit whose gradient is taken: 100 x cosine, as CLIP's trained scale


def relevance(attn_probs: torch.Tensor, attn_grads: torch.Tensor) -> torch.Tensor:
    """Chefer et al.'s relevance of each patch for the CLS token, from one attention block.

    ``attn_probs`` and ``attn_grads`` are ``[..., heads, T, T]`` (token 0 = CLS). The rule
    R <- R + cam @ R starts from the identity; with the single block CoW uses, R = I + cam.
    Returns ``[..., T - 1]``: the CLS row of R without the CLS column.
    """
    if attn_probs.shape != attn_grads.shape or attn_probs.ndim < 3:
        raise ValueError(f"relevance: attention {tuple(attn_probs.shape)} and gradient {tuple(attn_grads.shape)} "
                         "must share a [..., heads, T, T] shape")
    cam = (attn_grads * attn_probs).clamp(min=0).mean(dim=-3)
    eye = torch.eye(cam.shape[-1], dtype=cam.dtype, device=cam.device).expand_as(cam)
    rel = eye + cam @ eye
    return rel[..., 0, 1:]


@dataclass
class ClipGradConfig(CropConfig):
    weights: str | None = weights_field()
    point_stride: int = field(default=8, metadata={
        "help": "pixels of the 224 x 224 relevance map between stored points (its maximum is always stored)"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.point_stride < 1:
            raise ConfigError(f"clip-grad: point_stride must be >= 1, got {self.point_stride}")


@register_matcher("clip-grad")
class ClipGradMatcher(CropMatcher):
    """Score = max of 10 x the gradient relevance upsampled to the input size; points = that map's pixels."""

    Config = ClipGradConfig
    modality = Modality.TEXTUAL
    default_sigma = 0.85
    weights_spec = WEIGHTS
    paper = "CLIP on Wheels (Gadre et al., CVPR 2023), relevance after Chefer et al. (ICCV 2021)"
    version = 2  # what each version changed: docs/baselines.md

    def __init__(self, cfg: ClipGradConfig | None = None) -> None:
        super().__init__(cfg)
        self._model = None
        self._text: torch.Tensor | None = None  # (n_descriptions, dim), L2-normalised
        self._cache: dict[tuple[str, ...], torch.Tensor] = {}

    # ------------------------------------------------------------------ target
    def _prepare(self, target: Target) -> None:
        if self._model is None:
            self._model = self.weights_spec.load_pretrained(self.cfg.weights, f"matcher {self.display_name}",
                                                            _load_clipmodel).to(self.cfg.device)
            self._model.requires_grad_(False)  # only the attention probabilities need a gradient
        if target.descriptions not in self._cache:  # episodes share targets: encode each once
            self._cache[target.descriptions] = self._encode_descriptions(target.descriptions)
        self._text = self._cache[target.descriptions]

    @torch.no_grad()
    def _encode_descriptions(self, descriptions: tuple[str, ...]) -> torch.Tensor:
        """Each description through the 80 ImageNet templates, averaged, L2-normalised (CLIP's zero-shot recipe)."""
        import open_clip
        from open_clip.zero_shot_metadata import OPENAI_IMAGENET_TEMPLATES

        tokenizer = open_clip.get_tokenizer("ViT-B-32")
        prompts = [template(d) for d in descriptions for template in OPENAI_IMAGENET_TEMPLATES]
        ids = tokenizer(prompts).to(self.cfg.device)
        feats = F.normalize(self._model.get_text_features(input_ids=ids).pooler_output, dim=-1)
        feats = feats.reshape(len(descriptions), len(OPENAI_IMAGENET_TEMPLATES), -1).mean(dim=1)
        return F.normalize(feats, dim=-1)

    # ------------------------------------------------------------------ images
    def _pixels(self, crops: list[np.ndarray]) -> torch.Tensor:
        """Square crops -> CLIP input as CoW feeds it: ToTensor, torchvision's antialiased bicubic resize of a float
        tensor (which can overshoot [0, 1]; CoW does not clamp, so neither do we), CLIP normalisation."""
        from open_clip.constants import OPENAI_DATASET_MEAN, OPENAI_DATASET_STD

        size = self._model.config.vision_config.image_size
        mean = torch.tensor(OPENAI_DATASET_MEAN).view(1, 3, 1, 1)
        std = torch.tensor(OPENAI_DATASET_STD).view(1, 3, 1, 1)
        batch = []
        for crop in crops:
            x = torch.from_numpy(crop).permute(2, 0, 1)[None].float() / 255.0
            x = F.interpolate(x, size=(size, size), mode="bicubic", align_corners=False, antialias=True)
            batch.append(x)
        return ((torch.cat(batch) - mean) / std).to(self.cfg.device)

    def relevance_maps(self, crops: list[np.ndarray]) -> torch.Tensor:
        """(n_crops, n_descriptions, grid, grid) relevance of each patch for each description."""
        vision = self._model.vision_model
        with torch.no_grad():
            hidden = vision.pre_layrnorm(vision.embeddings(self._pixels(crops)))
            for layer in vision.encoder.layers[:-1]:
                hidden = layer(hidden, None)
        n_crops, n_text = hidden.shape[0], self._text.shape[0]
        hidden = hidden.repeat_interleave(n_text, dim=0)  # row i = crop i // n_text, description i % n_text
        probs = self._last_block_probs(hidden)
        logits = LOGIT_SCALE * (self._embed_from_probs(hidden, probs) * self._text.repeat(n_crops, 1)).sum(-1)
        (grads,) = torch.autograd.grad(logits.sum(), probs)  # rows are independent: the sum's gradient is per row
        rel = relevance(probs.detach(), grads)
        grid = int(round(rel.shape[-1] ** 0.5))
        return rel.reshape(n_crops, n_text, grid, grid)

    def _last_block_probs(self, hidden: torch.Tensor) -> torch.Tensor:
        attn = self._model.vision_model.encoder.layers[-1].self_attn
        with torch.no_grad():
            x = self._model.vision_model.encoder.layers[-1].layer_norm1(hidden)
            q, k = self._heads(attn.q_proj(x), attn.num_heads), self._heads(attn.k_proj(x), attn.num_heads)
            probs = torch.softmax((q @ k.transpose(-1, -2)) * attn.scale, dim=-1)
        return probs.requires_grad_(True)

    def _embed_from_probs(self, hidden: torch.Tensor, probs: torch.Tensor) -> torch.Tensor:
        """The rest of the last block and the image head, as a function of the attention probabilities."""
        layer = self._model.vision_model.encoder.layers[-1]
        attn = layer.self_attn
        x = layer.layer_norm1(hidden)
        v = self._heads(attn.v_proj(x), attn.num_heads)
        out = (probs @ v).transpose(1, 2).reshape(hidden.shape)
        h = hidden + attn.out_proj(out)
        h = h + layer.mlp(layer.layer_norm2(h))
        pooled = self._model.vision_model.post_layernorm(h[:, 0])
        return F.normalize(self._model.visual_projection(pooled), dim=-1)

    @staticmethod
    def _heads(x: torch.Tensor, n_heads: int) -> torch.Tensor:
        b, t, d = x.shape
        return x.reshape(b, t, n_heads, d // n_heads).transpose(1, 2)

    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        size = self._model.config.vision_config.image_size
        maps = RELEVANCE_SCALE * self.relevance_maps(crops).detach()
        # CoW's map per description, then the best description per pixel (PIN matches if any description does)
        up = F.interpolate(maps, size=(size, size), mode="bilinear", align_corners=False).amax(dim=1).cpu().numpy()
        stride = self.cfg.point_stride
        grid = np.arange(stride // 2, size, stride)
        gx, gy = (a.ravel() for a in np.meshgrid(grid, grid))
        results = []
        for crop, rmap, raw in zip(crops, up, maps.amax(dim=1).cpu().numpy()):
            h, w = crop.shape[:2]
            iy, ix = np.unravel_index(int(rmap.argmax()), rmap.shape)
            on_grid = iy % stride == stride // 2 and ix % stride == stride // 2
            rows, cols = (gy, gx) if on_grid else (np.append(gy, iy), np.append(gx, ix))
            # map pixel centres into crop pixels
            points = np.stack([(cols + 0.5) * w / size - 0.5, (rows + 0.5) * h / size - 0.5], 1)
            results.append(MatchResult(score=float(rmap[iy, ix]), points=np.clip(points, 0, [w - 1, h - 1]),
                                       point_scores=rmap[rows, cols], heatmap=raw))
        return results


def _load_clipmodel(source: str):
    """The eval-mode model from a hub id or a save_pretrained folder (through ``WeightsSpec.load_pretrained``)."""
    from transformers import CLIPModel

    return CLIPModel.from_pretrained(source).eval()
