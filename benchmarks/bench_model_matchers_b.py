"""CPU time per 640x360 frame of clip-grad, persam and persam-f at their real architecture sizes.

Weights are random (default configs: CLIP ViT-B/32, SAM ViT-B), since no hub weights can be
downloaded here and the cost of a forward pass does not depend on the values. Each model is
saved with save_pretrained and loaded through ``weights=`` like any local override.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from pin_match.frameset import Target
from pin_match.registry import create_matcher


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
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        paths = _save_models(Path(tmp))
        for name, model in (("clip-grad", "clip"), ("persam", "sam"), ("persam-f", "sam")):
            matcher = create_matcher(name, weights=str(paths[model]))
            start = time.perf_counter()
            matcher.prepare(target)
            prepare_s = time.perf_counter() - start
            matcher.match(images[0])
            start = time.perf_counter()
            for image in images[1:]:
                matcher.match(image)
            ms = 1000 * (time.perf_counter() - start) / frames
            out[name] = {"ms_per_frame": round(ms, 1), "prepare_s": round(prepare_s, 2), "frames": frames,
                         "threads": torch.get_num_threads()}
    print(f"{'matcher':<10} {'ms/frame':>10} {'prepare s':>10} {'frames':>7}")
    for name, row in out.items():
        print(f"{name:<10} {row['ms_per_frame']:>10.1f} {row['prepare_s']:>10.2f} {row['frames']:>7}")
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
