"""Weight-free matchers (sift, color): frames per second through the whole scoring engine, 1 vs 2 workers.

Target: >= 20 frames/s using both cores. Measured end to end (decode, prepare per episode,
match, write the table) on the synthetic frame-set, with a fresh cache each run.
"""

from __future__ import annotations

import tempfile
import time

from benchmarks.framesets import synthetic
from pin_match.scoring import score


def run(quick: bool = False) -> dict:
    fs = synthetic(4 if quick else 24, "synth_quick" if quick else "synth_default")
    out = {}
    print(f"{'matcher':10s} {'workers':>7s} {'frames':>6s} {'seconds':>8s} {'frames/s':>9s}")
    for name in ("sift", "color"):
        for workers in (1, 2):
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                table = score(fs, name, out=tmp, workers=workers, progress=False)
                dt = time.perf_counter() - t0
            fps = len(table.frames) / dt
            out[f"{name}_workers{workers}_fps"] = fps
            print(f"{name:10s} {workers:7d} {len(table.frames):6d} {dt:8.2f} {fps:9.1f}")
        out[f"{name}_scaling_2_vs_1"] = out[f"{name}_workers2_fps"] / out[f"{name}_workers1_fps"]
        print(f"{name}: 2 workers / 1 worker = {out[f'{name}_scaling_2_vs_1']:.2f}x; target >= 20 frames/s: "
              f"{'holds' if out[f'{name}_workers2_fps'] >= 20 else 'does not hold'}")
    return out
