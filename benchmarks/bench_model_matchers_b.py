"""CPU time per 640x360 frame of clip-grad, persam and persam-f at their real architecture sizes.

Weights are random (default configs: CLIP ViT-B/32, SAM ViT-B), since no hub weights can be
downloaded here and the cost of a forward pass does not depend on the values. Each model is
saved with save_pretrained and loaded through ``weights=`` like any local override.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.timing import time_random_models


def _save_models(root: Path) -> dict[str, Path]:
    from transformers import CLIPConfig, CLIPModel, SamConfig, SamModel

    paths = {"clip": root / "clip-vit-b32", "sam": root / "sam-vit-b"}
    CLIPModel(CLIPConfig()).save_pretrained(paths["clip"])
    SamModel(SamConfig()).save_pretrained(paths["sam"])
    return paths


def _options(paths: dict[str, str]) -> dict[str, dict]:
    return {name: {"weights": paths[model]} for name, model in (("clip-grad", "clip"), ("persam", "sam"),
                                                                 ("persam-f", "sam"))}


def run(quick: bool) -> dict:
    """Milliseconds per frame (mean over timed frames after one warm-up) and prepare seconds per matcher."""
    return time_random_models(_save_models, _options, quick)


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
