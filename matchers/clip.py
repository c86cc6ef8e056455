"""``clip``, ``clip-text``: CLIP's patches against reference prototypes or against descriptions (PIN's CLIP baselines).

Both run OpenAI's CLIP ViT-B/16 through open_clip; ``clip`` compares patches with one
prototype per reference view (as ``dino``), ``clip-text`` with one text feature per
description, each put through CLIP's zero-shot prompt templates.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from pin_match.contract import MatcherError, Modality, Target, WeightsSpec, register_matcher
from pin_match.matchers.common.backbones import OPEN_CLIP_FILES, OpenClipBackbone, PatchBackbone, TextBackbone
from pin_match.matchers.common.patch import PatchConfig, PatchSimilarityMatcher, ReferencePrototypeMatcher


def text_target(encode_text: Callable[[Sequence[str]], torch.Tensor], description: str,
                templates: Sequence[Callable[[str], str] | str]) -> torch.Tensor:
    """One description through the prompt templates: per-template features normalised, averaged, normalised.

    This is CLIP's zero-shot recipe (and CoW's); normalising before averaging keeps one
    template with a large feature norm from dominating.
    """
    prompts = [t(description) if callable(t) else t.format(description) for t in templates]
    feats = F.normalize(encode_text(prompts).float(), dim=-1)
    return F.normalize(feats.mean(0), dim=0)


@dataclass
class ClipConfig(PatchConfig):
    model_name: str = "ViT-B-16"
    img_size: int = 224
    quick_gelu: bool = True  # OpenAI's weights were trained with QuickGELU


# the file open_clip itself fetches first for this repository (its .bin twin holds the same tensors)
CLIP_WEIGHTS = WeightsSpec("timm/vit_base_patch16_clip_224.openai", filename="open_clip_model.safetensors",
                           license="MIT")
CLIP_PAPER = "Radford et al., Learning Transferable Visual Models From Natural Language Supervision, ICML 2021"


def _open_clip_backbone(matcher: PatchSimilarityMatcher) -> OpenClipBackbone:
    cfg = matcher.cfg
    return OpenClipBackbone(cfg.model_name, matcher.checkpoint(OPEN_CLIP_FILES), cfg.img_size,
                            cfg.quick_gelu, cfg.device)


@register_matcher("clip")
class ClipMatcher(ReferencePrototypeMatcher):
    """CLIP ViT-B/16 (OpenAI) at 224, reference prototypes and patches in the joint space."""

    Config = ClipConfig
    weights_spec = CLIP_WEIGHTS
    default_sigma = 0.575
    paper = CLIP_PAPER

    def _build_backbone(self) -> PatchBackbone:
        return _open_clip_backbone(self)


@register_matcher("clip-text")
class ClipTextMatcher(PatchSimilarityMatcher):
    """CLIP ViT-B/16 (OpenAI): patches against each description put through CLIP's 80 ImageNet templates."""

    Config = ClipConfig
    weights_spec = CLIP_WEIGHTS
    modality = Modality.TEXTUAL
    default_sigma = 0.28
    paper = CLIP_PAPER

    def _build_backbone(self) -> PatchBackbone:
        return _open_clip_backbone(self)

    def _target_vectors(self, target: Target) -> torch.Tensor:
        from open_clip.zero_shot_metadata import OPENAI_IMAGENET_TEMPLATES

        backbone = self.backbone
        if not hasattr(backbone, "encode_text"):
            raise MatcherError(f"matcher {self.display_name}: backbone {type(backbone).__name__} has no text encoder")
        text: TextBackbone = backbone
        return torch.stack([text_target(text.encode_text, d, OPENAI_IMAGENET_TEMPLATES) for d in target.descriptions])
