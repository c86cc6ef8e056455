"""OWL-ViT B/32 matchers: text queries (PIN's OWL) and the closest reference as query (PIN's image-to-image).

Text queries are, by default, each description as written, one query each: CLIP on Wheels'
``ClipOwl`` sends one sentence per target and no template average, and PIN feeds its
descriptions through that class. OWL-ViT reads 16 tokens (start and end included), so a
longer prompt is cut; the matcher says so once per target instead of cutting silently.

Both score a crop by its most confident box and keep the centres of the ``top_k`` most
confident boxes with their scores (CoW's "center_only"), so any sigma can be applied later
without scoring again. One vision pass per crop gives the box features, the boxes and the
pooled embedding that the image-to-image mode compares with the references.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from pin_match.contract import (
    ConfigError,
    CropConfig,
    CropMatcher,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    Target,
    WeightsSpec,
    register_matcher,
    weights_field,
)

WEIGHTS = WeightsSpec("google/owlvit-base-patch32", license="Apache-2.0")
QUERIES = ("descriptions", "category")
PROMPTS = {  # how each query text becomes OWL's text input(s)
    "description": ("{}",),              # the text alone (default)
    "a-photo-of": ("a photo of a {}.",),  # CoW's ClipOwl sentence, written there for class names
    "imagenet-80": None,                 # averaged over CLIP's 80 ImageNet templates
}
PAPER = "Minderer et al., Simple Open-Vocabulary Object Detection with Vision Transformers, ECCV 2022"


@lru_cache(maxsize=4)
def clip_tokenizer(max_length: int) -> Any:
    """OWL-ViT's tokenizer, built from the BPE vocabulary bundled with open_clip so no hub file is needed.

    OWL-ViT reads 16 tokens and pads with "!" (id 0); CLIP's vocabulary names its special
    tokens as open_clip does, so the ids are open_clip's.
    """
    from open_clip.tokenizer import SimpleTokenizer
    from transformers import CLIPTokenizer

    bpe = SimpleTokenizer()
    merges = [pair for pair, _ in sorted(bpe.bpe_ranks.items(), key=lambda kv: kv[1])]
    return CLIPTokenizer(vocab=dict(bpe.encoder), merges=merges, bos_token="<start_of_text>",
                         eos_token="<end_of_text>", unk_token="<end_of_text>", pad_token="!",
                         model_max_length=max_length)


def owl_verdict(logits: np.ndarray, boxes: np.ndarray, width: int, height: int, top_k: int) -> MatchResult:
    """One crop's verdict from OWL's class logits ``(P, Q)`` and boxes ``(P, 4)`` (cx, cy, w, h in 0-1).

    Box score = max over queries of the sigmoid of its logit; crop score = max box score;
    points = centres of the ``top_k`` best boxes in crop pixels (clipped into the crop).
    """
    logits = np.asarray(logits, np.float64).reshape(len(boxes), -1)
    box_scores = (0.5 * (1.0 + np.tanh(0.5 * logits))).max(axis=1)  # overflow-free sigmoid
    order = np.argsort(-box_scores, kind="stable")[:top_k]
    b = np.asarray(boxes, np.float64)[order] * [width, height, width, height]
    xyxy = np.stack([b[:, 0] - b[:, 2] / 2, b[:, 1] - b[:, 3] / 2, b[:, 0] + b[:, 2] / 2, b[:, 1] + b[:, 3] / 2], 1)
    xyxy = np.clip(xyxy, 0, [width, height, width, height])
    centres = np.clip(b[:, :2], 0, [width - 1, height - 1])
    scores = box_scores[order].astype(np.float32)
    return MatchResult(score=float(box_scores.max()) if len(box_scores) else 0.0, points=centres,
                       point_scores=scores, boxes=xyxy.astype(np.float32), box_scores=scores)


def closest_reference(observations: np.ndarray, references: np.ndarray) -> np.ndarray:
    """For each observation embedding ``(N, D)``, the index of the reference ``(R, D)`` of highest cosine."""
    obs = np.asarray(observations, np.float64)
    refs = np.asarray(references, np.float64)
    obs = obs / np.maximum(np.linalg.norm(obs, axis=1, keepdims=True), 1e-12)
    refs = refs / np.maximum(np.linalg.norm(refs, axis=1, keepdims=True), 1e-12)
    return np.argmax(obs @ refs.T, axis=1)


@dataclass
class OwlBaseConfig(CropConfig):
    weights: str | None = weights_field()
    top_k: int = field(default=100, metadata={"help": "boxes kept per crop, best first (their centres are the points)"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.top_k < 1:
            raise ConfigError(f"top_k={self.top_k}: keep at least one box")


class OwlBase(CropMatcher):
    """Loading, preprocessing and the shared forward pass of the OWL-ViT matchers."""

    default_sigma = 0.25  # PIN paper (its config file uses 0.2)
    weights_spec = WEIGHTS
    paper = PAPER

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self._model: Any = None
        self._processor: Any = None

    def _load(self) -> None:
        if self._model is not None:
            return
        from transformers import OwlViTForObjectDetection, OwlViTImageProcessor

        model = self.weights_spec.load_pretrained(self.cfg.weights, f"matcher {self.display_name}",
                                                  OwlViTForObjectDetection.from_pretrained)
        self._model = model.to(self.cfg.device).eval()
        side = model.config.vision_config.image_size  # the processor's own default (768) is B/32's; tiny models differ
        self._processor = OwlViTImageProcessor(size={"height": side, "width": side})

    def _embed(self, images: Sequence[np.ndarray]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Box features ``(N, P, D)``, boxes ``(N, P, 4)`` and the projected pooled embedding ``(N, E)``."""
        pixels = self._processor(images=[np.ascontiguousarray(im[..., :3]) for im in images],
                                 return_tensors="pt")["pixel_values"].to(self.cfg.device)
        feature_map, vision = self._model.image_embedder(pixel_values=pixels)
        n, h, w, d = feature_map.shape
        feats = feature_map.reshape(n, h * w, d)
        boxes = self._model.box_predictor(feats, feature_map)
        pooled = self._model.owlvit.visual_projection(vision.pooler_output)
        return feats, boxes, pooled

    def _verdicts(self, crops: Sequence[np.ndarray], feats: torch.Tensor, boxes: torch.Tensor,
                  queries: torch.Tensor) -> list[MatchResult]:
        """``queries`` is ``(N, Q, E)``: the class queries for each crop."""
        logits = self._model.class_predictor(feats, queries)[0].float().cpu().numpy()
        boxes = boxes.float().cpu().numpy()
        return [owl_verdict(lg, bx, crop.shape[1], crop.shape[0], self.cfg.top_k)
                for lg, bx, crop in zip(logits, boxes, crops)]


@dataclass
class OwlConfig(OwlBaseConfig):
    query: str = field(default="descriptions", metadata={"help": "descriptions (textual) or category (ablation)"})
    prompt: str = field(default="description", metadata={
        "help": "description (the text alone), a-photo-of (CoW's 'a photo of a {}.') or imagenet-80 (average of "
                "CLIP's 80 templates)"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.query not in QUERIES:
            raise ConfigError(f"query={self.query!r}: choose one of {QUERIES}")
        if self.prompt not in PROMPTS:
            raise ConfigError(f"prompt={self.prompt!r}: choose one of {tuple(PROMPTS)}")


class TruncationWarning(UserWarning):
    """A text query is longer than OWL-ViT's 16 tokens and is cut before its end."""


@register_matcher("owl")
class OwlMatcher(OwlBase):
    """PIN's OWL: each description (or, with ``query="category"``, the category name) is a class query.

    With ``query="category"`` the instance reads the category label, so its modality is
    category (the paper's ablation) and ``prepare`` keeps the label for it.
    """

    Config = OwlConfig
    modality = Modality.TEXTUAL
    version = 2  # what each version changed: docs/baselines.md

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        if self.cfg.query == "category":
            self.modality = Modality.CATEGORY
        self._queries: torch.Tensor | None = None
        self._warned: set[str] = set()  # targets whose truncated prompts were already reported

    @torch.inference_mode()
    def _prepare(self, target: Target) -> None:
        texts = target.descriptions if self.cfg.query == "descriptions" else (target.category,)
        if not all(t.strip() for t in texts):
            raise MatcherError(f"matcher {self.display_name}: target {target.object_id} has an empty "
                               f"{'description' if self.cfg.query == 'descriptions' else 'category'}")
        self._load()
        self._queries = self._text_queries(texts, target.object_id)

    def _text_queries(self, texts: Sequence[str], object_id: str) -> torch.Tensor:
        """One unit vector per text: its text embedding (averaged over the prompts when there are several)."""
        from open_clip.zero_shot_metadata import OPENAI_IMAGENET_TEMPLATES

        formats = PROMPTS[self.cfg.prompt]
        templates = OPENAI_IMAGENET_TEMPLATES if formats is None else [f.format for f in formats]
        prompts = [t(text) for text in texts for t in templates]
        limit = self._model.config.text_config.max_position_embeddings
        tokenizer = clip_tokenizer(limit)
        self._warn_truncated(tokenizer, prompts, limit, object_id)
        tokens = tokenizer(prompts, padding="max_length", truncation=True, return_tensors="pt").to(self.cfg.device)
        emb = self._model.owlvit.get_text_features(input_ids=tokens["input_ids"],
                                                   attention_mask=tokens["attention_mask"]).pooler_output
        emb = F.normalize(emb.float(), dim=-1).reshape(len(texts), len(templates), -1).mean(1)
        return F.normalize(emb, dim=-1)

    def _warn_truncated(self, tokenizer: Any, prompts: Sequence[str], limit: int, object_id: str) -> None:
        """One warning per target listing the prompts OWL-ViT will not read to the end (start and end tokens count)."""
        if object_id in self._warned:
            return
        lengths = [len(ids) for ids in tokenizer(list(prompts), truncation=False)["input_ids"]]
        cut = sorted({p for p, n in zip(prompts, lengths) if n > limit})
        if cut:
            self._warned.add(object_id)
            warnings.warn(f"matcher {self.display_name}: target {object_id}: {len(cut)} prompt(s) longer than "
                          f"OWL-ViT's {limit} tokens are cut before their end, e.g. {cut[0]!r} "
                          f"({max(lengths)} tokens at most)", TruncationWarning, stacklevel=2)

    @torch.inference_mode()
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        feats, boxes, _ = self._embed(crops)
        queries = self._queries.to(feats.dtype)[None].expand(len(crops), -1, -1)
        return self._verdicts(crops, feats, boxes, queries)


@register_matcher("owl-image")
class OwlImageMatcher(OwlBase):
    """PIN's image-to-image OWL: per crop, the reference view closest to it (cosine of OWL's projected
    pooled embeddings) is the class query. References are given as stored (RGB, alpha dropped)."""

    Config = OwlBaseConfig
    modality = Modality.VISUAL

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self._references: torch.Tensor | None = None

    @torch.inference_mode()
    def _prepare(self, target: Target) -> None:
        self._load()
        self._references = self._embed(target.views)[2].float()

    @torch.inference_mode()
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        feats, boxes, pooled = self._embed(crops)
        pick = closest_reference(pooled.float().cpu().numpy(), self._references.cpu().numpy())
        queries = self._references[torch.from_numpy(pick)][:, None].to(feats.dtype)
        return self._verdicts(crops, feats, boxes, queries)
