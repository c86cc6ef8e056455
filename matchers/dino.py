"""``dino``, ``dinov2``: reference prototypes on a timm ViT's patch tokens (PIN's DINO and DINOv2 baselines).

One matcher, ``TimmPrototypeMatcher``; the two networks are presets (``DINO_PRESETS``): the
timm model, its input size, its weights, PIN's sigma and the paper.
"""

from __future__ import annotations

from pin_match.contract import Preset, WeightsSpec, register_matcher
from pin_match.matchers.common.backbones import TIMM_FILES, PatchBackbone, TimmBackbone
from pin_match.matchers.common.patch import ReferencePrototypeMatcher

DINO_PRESETS = {
    "dino": Preset(
        config={"model_name": "vit_base_patch16_224.dino", "img_size": 224},
        weights_spec=WeightsSpec("timm/vit_base_patch16_224.dino", filename="model.safetensors", license="apache-2.0"),
        default_sigma=0.575,
        paper="Caron et al., Emerging Properties in Self-Supervised Vision Transformers, ICCV 2021"),
    "dinov2": Preset(
        config={"model_name": "vit_base_patch14_dinov2.lvd142m", "img_size": 518},
        weights_spec=WeightsSpec("timm/vit_base_patch14_dinov2.lvd142m", filename="model.safetensors",
                                 license="apache-2.0"),
        default_sigma=0.5,
        paper="Oquab et al., DINOv2: Learning Robust Visual Features without Supervision, TMLR 2024"),
}


class TimmPrototypeMatcher(ReferencePrototypeMatcher):
    """Mask-weighted reference prototypes against the patch tokens of the timm ViT its preset names."""

    def _build_backbone(self) -> PatchBackbone:
        cfg = self.cfg
        return TimmBackbone(cfg.model_name, self.checkpoint(TIMM_FILES), cfg.img_size, cfg.device)


@register_matcher("dino")
class DinoMatcher(TimmPrototypeMatcher, preset=DINO_PRESETS["dino"]):
    """DINO ViT-B/16 (ImageNet-1k, self-supervised) at 224: 14 x 14 patches."""


@register_matcher("dinov2")
class Dinov2Matcher(TimmPrototypeMatcher, preset=DINO_PRESETS["dinov2"]):
    """DINOv2 ViT-B/14 (LVD-142M) at 518: 37 x 37 patches."""
