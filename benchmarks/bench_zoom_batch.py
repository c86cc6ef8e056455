"""``verify``'s zoom for a house's three episodes in one batch against one batch per episode, same crops.

Issue 73's "one pass per house": a batch of 8 walk frames read by 3 episodes gives 3 candidate crops per
frame and target, 24 crops an episode, 72 a house. The crops' boxes depend on the target, so no crop is
shared; what one batch could save is the network's fixed cost per call. Both sides embed the same 72 crops
(boxes of 60-250 px cut from the real look-alikes' val frames, drawn from seed 0) with ``verify``'s zoom
network (``effnet`` at 256 px): three calls of 24, or one of 72. The largest difference of the two
outputs is printed beside the times (docs/performance.md).

``python -m benchmarks.bench_zoom_batch [--quick]``.
"""

from __future__ import annotations

import numpy as np
import torch

from benchmarks.bench_network_share import real_lookalikes
from benchmarks.loadavg import load_1min
from benchmarks.timing import fastest
from pin_match import create_matcher

EPISODES, PER_EPISODE = 3, 24  # a house's episodes; crops an episode's batch of 8 frames gives (3 candidates each)


def _crops(count: int) -> list[np.ndarray]:
    fs = real_lookalikes().split("val")
    frames = [fs.image(f) for f in fs.frames.frame_id[:8]]
    rng = np.random.default_rng(0)
    crops = []
    for k in range(count):
        image = frames[k % len(frames)]
        w, h = (int(v) for v in rng.integers(60, 251, 2))
        x, y = int(rng.integers(0, image.shape[1] - w)), int(rng.integers(0, image.shape[0] - h))
        crops.append(np.ascontiguousarray(image[y:y + h, x:x + w]))
    return crops


def run(quick: bool) -> dict:
    backbone = create_matcher("verify").zoomer.backbone
    crops = _crops(EPISODES * PER_EPISODE)
    with torch.inference_mode():
        apart = torch.cat([backbone.encode(crops[i:i + PER_EPISODE]).patches
                           for i in range(0, len(crops), PER_EPISODE)])
        together = backbone.encode(crops).patches
        diff = float((apart - together).abs().max())

        def per_episode():
            return [backbone.encode(crops[i:i + PER_EPISODE]) for i in range(0, len(crops), PER_EPISODE)]

        before = load_1min()
        times = fastest({"a batch per episode": per_episode, "one batch a house": lambda: backbone.encode(crops)},
                        repeats=2 if quick else 3)
    out = dict(crops=len(crops), input_px=backbone.input_size, max_abs_difference=diff,
               seconds={k: round(t.wall_s, 3) for k, t in times.items()},
               ratio=round(times["one batch a house"].wall_s / times["a batch per episode"].wall_s, 3),
               load={"before": before, "after": load_1min()})
    print(f"verify's zoom on {len(crops)} crops at {backbone.input_size} px: " + ", ".join(
        f"{k} {v:.2f} s" for k, v in out["seconds"].items()) + f"; one batch / per episode {out['ratio']:.2f}; "
        f"largest difference {diff:.2e}; load {out['load']['before']} -> {out['load']['after']}")
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
