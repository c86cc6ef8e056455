"""CPU time per 640x360 frame of superglue, lightglue, ieve, owl and owl-image at real architecture sizes.

Weights are random (default configs: SuperPoint + SuperGlue, SuperPoint + LightGlue,
OWL-ViT B/32), since no hub weights can be downloaded here and a forward pass costs the same
whatever the values. Each model is saved with save_pretrained and loaded through the
matchers' own ``weights=`` path. Random SuperPoint weights fire everywhere, so every image
hits the 1024-keypoint cap: the keypoint figures are the worst case of PIN's settings.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import torch

from benchmarks.timing import time_matchers
from pin_match.frameset import Target


def _target() -> Target:
    """PIN-sized references (1280x960 RGBA): a textured disc, so SuperPoint finds keypoints on the object."""
    rng = np.random.default_rng(1)
    view = np.zeros((1280, 960, 4), np.uint8)
    yy, xx = np.mgrid[:1280, :960]
    inside = (yy - 640) ** 2 + (xx - 480) ** 2 < 350 ** 2
    view[..., :3] = rng.integers(0, 256, (1280, 960, 3), dtype=np.uint8)
    view[inside, 3] = 255
    return Target("bench", "mug", (view, view, view),
                  ("a red ceramic mug with a white handle", "a mug on the kitchen table", "a red cup"))


def _save_models(root: Path) -> dict[str, Path]:
    from transformers import (
        LightGlueConfig,
        LightGlueForKeypointMatching,
        OwlViTConfig,
        OwlViTForObjectDetection,
        SuperGlueConfig,
        SuperGlueForKeypointMatching,
    )

    torch.manual_seed(0)
    paths = {"superglue": root / "superglue", "lightglue": root / "lightglue", "owl": root / "owlvit-b32"}
    SuperGlueForKeypointMatching(SuperGlueConfig()).save_pretrained(paths["superglue"])
    LightGlueForKeypointMatching(LightGlueConfig()).save_pretrained(paths["lightglue"])
    OwlViTForObjectDetection(OwlViTConfig()).save_pretrained(paths["owl"])
    return paths


def run(quick: bool) -> dict:
    """Milliseconds per frame (mean over timed frames after one warm-up) and prepare seconds per matcher."""
    frames = 1 if quick else 3
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (640, 360, 3), dtype=np.uint8) for _ in range(frames + 1)]
    target = _target()
    with tempfile.TemporaryDirectory() as tmp:
        paths = {k: str(v) for k, v in _save_models(Path(tmp)).items()}
        options = {
            "superglue": {"weights": paths["superglue"]},
            "lightglue": {"weights": paths["lightglue"]},
            "ieve": {"gate_weights": paths["owl"], "keypoints_weights": paths["lightglue"]},
            "owl": {"weights": paths["owl"]},
            "owl-image": {"weights": paths["owl"]},
        }
        return time_matchers(options, target, images)


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
