"""Time model-backed matchers the same way: prepare once, one warm-up frame, then ms per frame."""

from __future__ import annotations

import time

import numpy as np
import torch

from pin_match import Target, create_matcher


def bench_inputs(quick: bool) -> tuple[Target, list[np.ndarray]]:
    """A PIN-sized target (1280x960 RGBA references: a textured disc, so keypoint detectors find the object)
    and random 640x360 frames: one warm-up plus 1 (quick) or 3 timed."""
    rng = np.random.default_rng(1)
    view = np.zeros((1280, 960, 4), np.uint8)
    yy, xx = np.mgrid[:1280, :960]
    view[..., :3] = rng.integers(0, 256, (1280, 960, 3), dtype=np.uint8)
    view[(yy - 640) ** 2 + (xx - 480) ** 2 < 350 ** 2, 3] = 255
    target = Target("bench", "mug", (view, view, view),
                    ("a red ceramic mug with a white handle", "a mug on the kitchen table", "a red cup"))
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (640, 360, 3), dtype=np.uint8) for _ in range(2 if quick else 4)]
    return target, images


def time_matchers(options: dict[str, dict], target: Target, images: list[np.ndarray]) -> dict[str, dict]:
    """``options`` maps a matcher name to its config overrides; ``images[0]`` is the warm-up frame."""
    out = {}
    frames = len(images) - 1
    for name, kwargs in options.items():
        matcher = create_matcher(name, **kwargs)
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
