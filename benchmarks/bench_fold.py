"""Folded batch norms: ``effnet``'s network with its norms folded (as every CNN trunk now runs) against the same
network with its norms as loaded, on the same inputs.

The inputs are what ``effnet`` feeds its network for the first val frames of the real look-alikes
(``pin-match data build core50 OUT --variant approach``): each frame's crops, resized and
normalised before the clock. Both sides run the one network class (``FeatureMapBackbone.feature_map``);
the unfolded side is a second instance built with folding turned off. The largest difference of the
two feature maps is printed beside the times (docs/performance.md).

``python -m benchmarks.bench_fold [--quick]``.
"""

from __future__ import annotations

import argparse
from unittest import mock

import torch

from benchmarks.bench_network_share import real_lookalikes
from benchmarks.loadavg import load_1min
from benchmarks.timing import fastest
from pin_match import create_matcher
from pin_match.contract import crop_boxes
from pin_match.matchers.common.backbones import network_input


def run(quick: bool) -> dict:
    fs = real_lookalikes().split("val")
    frames = [fs.image(f) for f in fs.frames.frame_id[:4 if quick else 16]]
    unfolded = create_matcher("effnet")
    with mock.patch("pin_match.matchers.common.backbones.fold_batch_norms", lambda *a: 0):
        plain = unfolded.backbone
    folded = create_matcher("effnet").backbone
    crops = [image[c.y0:c.y0 + c.height, c.x0:c.x0 + c.width] for image in frames
             for c in crop_boxes(image.shape[0], image.shape[1], unfolded.cfg.crops)]
    x = network_input(folded, crops)
    batches = [x[i:i + 16] for i in range(0, len(x), 16)]
    with torch.inference_mode():
        diff = max(float((folded.feature_map(b) - plain.feature_map(b)).abs().max()) for b in batches)
    before = load_1min()
    times = fastest({"norms as loaded": lambda: [plain.feature_map(b) for b in batches],
                     "norms folded": lambda: [folded.feature_map(b) for b in batches]}, repeats=2 if quick else 3)
    out = dict(crops=len(crops), input_px=folded.input_size, max_abs_difference=diff,
               seconds={k: round(t.wall_s, 3) for k, t in times.items()},
               ratio=round(times["norms folded"].wall_s / times["norms as loaded"].wall_s, 3),
               load={"before": before, "after": load_1min()},
               norms_left=sum(isinstance(m, torch.nn.BatchNorm2d) for m in folded.trunk.modules()),
               norms_as_loaded=sum(isinstance(m, torch.nn.BatchNorm2d) for m in plain.trunk.modules()))
    print(f"effnet network on {len(crops)} crops at {folded.input_size} px: " + ", ".join(
        f"{k} {v:.2f} s" for k, v in out["seconds"].items()) + f"; folded / as loaded {out['ratio']:.2f}; "
        f"largest difference {diff:.2e}; norms {out['norms_as_loaded']} -> {out['norms_left']}; "
        f"load {out['load']['before']} -> {out['load']['after']}")
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    run(p.parse_args().quick)


if __name__ == "__main__":
    main()
