"""CPU time per 640x360 frame of superglue, lightglue, ieve, owl and owl-image at real architecture sizes.

Weights are random (default configs: SuperPoint + SuperGlue, SuperPoint + LightGlue,
OWL-ViT B/32), since no hub weights can be downloaded here and a forward pass costs the same
whatever the values. Each model is saved with save_pretrained and loaded through the
matchers' own ``weights=`` path. Random SuperPoint weights fire everywhere, so every image
hits the 1024-keypoint cap: the keypoint figures are the worst case of PIN's settings.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.timing import time_random_models


def _save_models(root: Path) -> dict[str, Path]:
    from transformers import (
        LightGlueConfig,
        LightGlueForKeypointMatching,
        OwlViTConfig,
        OwlViTForObjectDetection,
        SuperGlueConfig,
        SuperGlueForKeypointMatching,
    )

    paths = {"superglue": root / "superglue", "lightglue": root / "lightglue", "owl": root / "owlvit-b32"}
    SuperGlueForKeypointMatching(SuperGlueConfig()).save_pretrained(paths["superglue"])
    LightGlueForKeypointMatching(LightGlueConfig()).save_pretrained(paths["lightglue"])
    OwlViTForObjectDetection(OwlViTConfig()).save_pretrained(paths["owl"])
    return paths


def _options(paths: dict[str, str]) -> dict[str, dict]:
    return {
        "superglue": {"weights": paths["superglue"]},
        "lightglue": {"weights": paths["lightglue"]},
        "ieve": {"gate_cfg": {"weights": paths["owl"]}},  # its keypoint part, disk-lightglue, carries its weights
        "owl": {"weights": paths["owl"]},
        "owl-image": {"weights": paths["owl"]},
    }


def run(quick: bool) -> dict:
    """Milliseconds per frame (mean over timed frames after one warm-up) and prepare seconds per matcher."""
    return time_random_models(_save_models, _options, quick)


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
