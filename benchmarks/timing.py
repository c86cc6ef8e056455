"""Time model-backed matchers the same way: prepare once, one warm-up frame, then ms per frame."""

from __future__ import annotations

import time

import numpy as np
import torch

from pin_match import Target, create_matcher


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
