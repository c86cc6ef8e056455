"""Weight-free matchers (sift, color): frames per second through the whole scoring engine, 1 vs 2 workers.

Target: >= 20 frames/s using both cores. Measured end to end (decode, prepare per episode,
match, write the table) on the synthetic frame-set, with a fresh cache each run.
"""

from __future__ import annotations

from benchmarks.framesets import synthetic
from benchmarks.timing import timed_score


def run(quick: bool = False) -> dict:
    fs = synthetic("synth_quick", seed=0, episodes=4) if quick else synthetic("synth_default", seed=0, episodes=24)
    out = {}
    print(f"{'matcher':10s} {'workers':>7s} {'frames':>6s} {'seconds':>8s} {'frames/s':>9s}")
    for name in ("sift", "color"):
        for workers in (1, 2):
            table, dt = timed_score(fs, name, workers)
            fps = len(table.frames) / dt
            out[f"{name}_workers{workers}_fps"] = fps
            print(f"{name:10s} {workers:7d} {len(table.frames):6d} {dt:8.2f} {fps:9.1f}")
        out[f"{name}_scaling_2_vs_1"] = out[f"{name}_workers2_fps"] / out[f"{name}_workers1_fps"]
        print(f"{name}: 2 workers / 1 worker = {out[f'{name}_scaling_2_vs_1']:.2f}x; target >= 20 frames/s: "
              f"{'holds' if out[f'{name}_workers2_fps'] >= 20 else 'does not hold'}")
    return out
