"""effnet on the real-photo set: frames/s through the scoring engine, and the matcher against its bare network.

Figures (docs/performance.md):
- frames/s of ``pin-match score`` on the 72 real-photo frames at the default config (decode,
  two PIN crops per frame, prepare per episode, match, write the table), 1 and 2 worker threads;
- per config (the default, ``layer=head img_size=448``, and ``layer=blocks.3 img_size=224``): frames/s of
  the bare network (``feature_map``: the trunk's forward pass alone, channels-last, on the frames' crops
  already put through the backbone's own ``network_input``, one frame's two crops per pass) and of
  ``matcher.match`` on the same frames (which adds cropping, resizing, normalising, the cosine max and the
  result), measured side by side, interleaved, and their ratio. Target: matcher / bare >= 0.9. A third
  side, the same network and crops in NCHW memory format, gives what channels-last buys.

``python -m benchmarks.bench_effnet [--quick]``.
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from benchmarks.framesets import real_photos
from benchmarks.timing import fastest, timed_score
from pin_match import create_matcher
from pin_match.contract.crops import crop_boxes
from pin_match.matchers.common.backbones import network_input

CONFIGS = {"default (head, 448 px)": {}, "layer=blocks.3 img_size=224": {"layer": "blocks.3", "img_size": 224}}
TARGET_RATIO = 0.9


def network_inputs(matcher, images: list[np.ndarray]) -> list[torch.Tensor]:
    """Per frame, the batch ``matcher.match`` runs its network on: the frame's crops by the matcher's policy, through
    the backbone's own preprocessing (``network_input``, which ``encode`` calls), one forward pass per frame."""
    return [network_input(matcher.backbone, [c.take(im) for c in crop_boxes(*im.shape[:2], matcher.cfg.crops)])
            for im in images]


def side_by_side(fs, overrides: dict, n_frames: int, repeats: int) -> dict:
    """Bare network vs ``matcher.match`` on the same frames, interleaved; the fastest run of each side."""
    matcher = create_matcher("effnet", **overrides)
    episode = fs.episodes.iloc[0]
    matcher.prepare(fs.target(episode.target_object_id))
    images = [fs.image(f) for f in fs.frames.frame_id[:n_frames]]
    bb = matcher.backbone
    batches = network_inputs(matcher, images)
    nchw_trunk = copy.deepcopy(bb.trunk).to(memory_format=torch.contiguous_format)
    nchw_batches = [x.contiguous() for x in batches]

    @torch.inference_mode()
    def bare_nchw() -> None:
        for x in nchw_batches:
            nchw_trunk(x)

    sides = {"bare": lambda: [bb.feature_map(x) for x in batches],
             "matcher": lambda: [matcher.match(im) for im in images], "bare_nchw": bare_nchw}
    fastest(sides)  # warm-up, every side
    best = {side: t.wall_s for side, t in fastest(sides, repeats).items()}
    return dict(config=str(matcher.cfg), frames=n_frames, repeats=repeats,
                bare_fps=round(n_frames / best["bare"], 2), matcher_fps=round(n_frames / best["matcher"], 2),
                ratio=round(best["bare"] / best["matcher"], 3), bare_nchw_fps=round(n_frames / best["bare_nchw"], 2),
                channels_last_speedup=round(best["bare_nchw"] / best["bare"], 3))


def run(quick: bool = False) -> dict:
    fs = real_photos()
    out: dict = {"torch_threads": torch.get_num_threads()}
    print(f"pin-match score, effnet default, {len(fs.frames)} real-photo frames")
    print(f"{'workers':>7s} {'frames':>6s} {'seconds':>8s} {'frames/s':>9s}")
    for workers in (1,) if quick else (1, 2):
        table, dt = timed_score(fs, "effnet", workers)
        out[f"score_workers{workers}_fps"] = round(len(table.frames) / dt, 2)
        print(f"{workers:7d} {len(table.frames):6d} {dt:8.2f} {len(table.frames) / dt:9.2f}")
    print(f"\nbare network vs matcher.match, side by side (target matcher/bare >= {TARGET_RATIO}):")
    print(f"{'config':<26} {'bare frames/s':>14} {'matcher frames/s':>17} {'ratio':>6}  target         "
          f"{'bare NCHW frames/s':>18} {'channels-last speed-up':>22}")
    for label, overrides in CONFIGS.items():
        row = out[label] = side_by_side(fs, overrides, 3 if quick else 12, 1 if quick else 6)
        print(f"{label:<26} {row['bare_fps']:>14.2f} {row['matcher_fps']:>17.2f} {row['ratio']:>6.3f}  "
              f"{'holds' if row['ratio'] >= TARGET_RATIO else 'does not hold':<14} {row['bare_nchw_fps']:>18.2f} "
              f"{row['channels_last_speedup']:>21.2f}x", flush=True)
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
