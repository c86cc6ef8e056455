"""CPU time per 640x360 frame of clip-grad, persam and persam-f at their real architecture sizes.

Weights are random (default configs: CLIP ViT-B/32, SAM ViT-B), since no hub weights can be
downloaded here and the cost of a forward pass does not depend on the values. Each model is
saved with save_pretrained and loaded through ``weights=`` like any local override.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import torch

from benchmarks.timing import time_matchers
from pin_match.frameset import Target


def _target() -> Target:
    view = np.zeros((1280, 960, 4), np.uint8)  # PIN's reference size, a disc as the alpha mask
    yy, xx = np.mgrid[:1280, :960]
    inside = (yy - 640) ** 2 + (xx - 480) ** 2 < 350 ** 2
    view[inside] = (180, 40, 40, 255)
    return Target("bench", "mug", (view, view, view), ("a red mug on a table",) * 3)


def _save_models(root: Path) -> dict[str, Path]:
    from transformers import CLIPConfig, CLIPModel, SamConfig, SamModel

    torch.manual_seed(0)
    paths = {"clip": root / "clip-vit-b32", "sam": root / "sam-vit-b"}
    CLIPModel(CLIPConfig()).save_pretrained(paths["clip"])
    SamModel(SamConfig()).save_pretrained(paths["sam"])
    return paths


def run(quick: bool) -> dict:
    """Milliseconds per frame (mean over timed frames after one warm-up) and prepare seconds per matcher."""
    frames = 1 if quick else 3
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (640, 360, 3), dtype=np.uint8) for _ in range(frames + 1)]
    target = _target()
    with tempfile.TemporaryDirectory() as tmp:
        paths = _save_models(Path(tmp))
        options = {name: {"weights": str(paths[model])}
                   for name, model in (("clip-grad", "clip"), ("persam", "sam"), ("persam-f", "sam"))}
        return time_matchers(options, target, images)


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
