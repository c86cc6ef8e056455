"""``dino``, ``dinov2``: reference prototypes on a timm ViT's patch tokens (PIN's DINO and DINOv2 baselines)."""

from __future__ import annotations

from dataclasses import dataclass

from pin_match.contract import WeightsSpec, register_matcher
from pin_match.matchers.backbones import TIMM_FILES, PatchBackbone, TimmBackbone
from pin_match.matchers.patch import PatchConfig, ReferencePrototypeMatcher


@dataclass
class DinoConfig(PatchConfig):
    model_name: str = "vit_base_patch16_224.dino"
    img_size: int = 224


@dataclass
class Dinov2Config(PatchConfig):
    model_name: str = "vit_base_patch14_dinov2.lvd142m"
    img_size: int = 518


class TimmPrototypeMatcher(ReferencePrototypeMatcher):
    def _build_backbone(self) -> PatchBackbone:
        cfg = self.cfg
        return TimmBackbone(cfg.model_name, self.checkpoint(TIMM_FILES), cfg.img_size, cfg.device)


@register_matcher("dino")
class DinoMatcher(TimmPrototypeMatcher):
    """DINO ViT-B/16 (ImageNet-1k, self-supervised) at 224: 14 x 14 patches."""

    Config = DinoConfig
    weights_spec = WeightsSpec("timm/vit_base_patch16_224.dino", filename="model.safetensors", license="apache-2.0")
    default_sigma = 0.575
    paper = "Caron et al., Emerging Properties in Self-Supervised Vision Transformers, ICCV 2021"


@register_matcher("dinov2")
class Dinov2Matcher(TimmPrototypeMatcher):
    """DINOv2 ViT-B/14 (LVD-142M) at 518: 37 x 37 patches."""

    Config = Dinov2Config
    weights_spec = WeightsSpec("timm/vit_base_patch14_dinov2.lvd142m", filename="model.safetensors",
                               license="apache-2.0")
    default_sigma = 0.5
    paper = "Oquab et al., DINOv2: Learning Robust Visual Features without Supervision, TMLR 2024"
