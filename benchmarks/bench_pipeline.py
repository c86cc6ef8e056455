"""Pipeline overhead: scoring a frame-set through pin_match vs the bare backbone forward on the same crops.

Both sides use the same DINO ViT-B/16 @224 (random weights saved to a local file and loaded
through the matcher's real ``weights=`` path), the same crops and the same batch size. The
bare side gets its crops decoded, cut and resized before the clock starts and times only
``forward_features``; the pin_match side is the whole job: decode (in worker threads),
crop, resize, the forward pass, prototypes per target, similarity, and writing the table.
Ratio = bare time / pin_match time (target >= 0.9).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import torch

from benchmarks.framesets import synthetic
from benchmarks.timing import once
from pin_match.contract.crops import crop_boxes
from pin_match.contract.registry import create_matcher
from pin_match.matchers.common.backbones import network_input
from pin_match.scoring import RunOptions, score_to_file

BATCH = 8  # frames per batch = 16 crops per forward


def run(quick: bool = False) -> dict:
    import timm
    from safetensors.torch import save_file

    model_name, img_size = ("test_vit", 64) if quick else ("vit_base_patch16_224", 224)
    fs = synthetic("synth_pipeline_quick", seed=0, episodes=2) if quick else \
        synthetic("synth_pipeline", seed=0, episodes=4)
    with tempfile.TemporaryDirectory() as tmp:
        torch.manual_seed(0)
        weights = Path(tmp) / "vit.safetensors"
        save_file(timm.create_model(model_name, pretrained=False, num_classes=0).state_dict(), str(weights))
        overrides = dict(model_name=model_name, img_size=img_size, weights=str(weights))

        matcher = create_matcher("dino", **overrides)
        backbone = matcher.backbone  # built once, before any clock, on both sides
        t_pipeline = once(lambda: score_to_file(fs, matcher, out=Path(tmp) / "scores",
                                                run=RunOptions(batch_size=BATCH, progress=False))).wall_s

        # the matcher's own crops and preprocessing (``network_input``, which its ``encode`` calls), before the clock
        images = (fs.image(f) for f in fs.frames.sort_values(["episode_id", "step"]).frame_id)
        crops = [c.take(im) for im in images for c in crop_boxes(*im.shape[:2], matcher.cfg.crops)]
        tensors = [network_input(backbone, crops[i:i + 2 * BATCH]) for i in range(0, len(crops), 2 * BATCH)]

        @torch.inference_mode()
        def bare() -> None:
            for x in tensors:
                backbone.model.forward_features(x)

        t_bare = once(bare).wall_s
    n = len(fs.frames)
    out = dict(model=model_name, frames=n, crops=len(crops), batch_frames=BATCH, pipeline_s=t_pipeline,
               bare_forward_s=t_bare, ratio_bare_over_pipeline=t_bare / t_pipeline,
               pipeline_fps=n / t_pipeline, bare_fps=n / t_bare)
    print(f"{model_name} @{img_size}, {n} frames ({len(crops)} crops), batch {BATCH} frames:")
    print(f"  bare forward_features: {t_bare:7.2f} s  ({n / t_bare:.2f} frames/s)")
    print(f"  pin_match scoring:     {t_pipeline:7.2f} s  ({n / t_pipeline:.2f} frames/s)")
    print(f"  ratio bare / pin_match = {t_bare / t_pipeline:.3f} (target >= 0.9: "
          f"{'holds' if t_bare / t_pipeline >= 0.9 else 'does not hold'})")
    return out
