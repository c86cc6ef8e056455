"""Scoring on a Dask LocalCluster vs in this process: fixed cost and per-frame rate of each setup.

Runs at 128, 512 and 2,048 frames (procedural 640x360 frames, 32 per episode; 64 and 128
with ``--quick``), matcher ``effnet`` at ``layer=blocks.3 img_size=224`` (its cheapest
useful config: the less a frame costs, the more the cluster's own overhead shows),
each run from the frame-set's path to the finished table in a fresh cache.
Setups:
- in-process: ``workers=1`` (one matching thread, frames decoded ahead in a second one),
  torch using every core;
- 1 worker: ``connect("local", workers=1)``, one worker process with every core;
- 1 single-thread worker and 2 single-thread workers (one torch thread each).
Per setup, wall seconds against frames is fitted with a line: the intercept is the fixed
cost per run (registering the worker plugin, loading the frame-set, task round trips, the
assembly), the slope the seconds per frame. Cluster start-up and the first (cold) run, which
imports the matcher's modules and builds it in each worker, are measured apart: a cluster
serves many runs. Sizes and setups alternate, so load from other jobs hits all alike.

Targets: 1 worker within 10 % of in-process wall time at 2,048 frames; 2 single-thread workers
>= 1.7x one single-thread worker (wall at 2,048 frames). Beside each wall time, the CPU seconds
of this process and all its children (the workers, their decode-ahead threads, the scheduler)
give the cores a setup keeps busy: on a machine of C cores, a setup that keeps k busy with one
worker can speed up at most C / k with more.

``python -m benchmarks.bench_distributed [--quick]``.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.framesets import procedural
from pin_match.contract.registry import create_matcher
from pin_match.scoring import RunOptions, score_to_file
from pin_match.scoring.cluster import connect, local_cluster

SIZES = (128, 512, 2048)
QUICK_SIZES = (64, 128)
FRAMES_PER_EPISODE = 32
SETUPS = ("in-process", "1 worker", "1 single-thread worker", "2 single-thread workers")


def start_clients(matcher, warm_fs) -> tuple[dict, dict]:
    """The three clusters, each started and warmed by one cold run; seconds of start-up and of the cold run."""
    clients, startup = {}, {}
    cores = os.cpu_count() or 1
    makers = {"1 worker": lambda: connect("local", workers=1),
              "1 single-thread worker": lambda: local_cluster(1, torch_threads=1),
              "2 single-thread workers": lambda: local_cluster(min(2, cores), torch_threads=1)}
    for label, make in makers.items():
        t0 = time.perf_counter()
        clients[label] = make()
        clients[label].wait_for_workers(len(clients[label].nthreads()) or 1)
        t1 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            score_to_file(warm_fs.root, matcher, out=tmp, run=RunOptions(progress=False, client=clients[label]))
        startup[label] = {"start_s": round(t1 - t0, 2), "cold_run_s": round(time.perf_counter() - t1, 2)}
    return clients, startup


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and every process under it, so far."""
    import psutil

    me = psutil.Process()
    total = 0.0
    for process in [me, *me.children(recursive=True)]:
        try:
            times = process.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += times.user + times.system
    return total


def fit(frames: list[int], seconds: list[float]) -> tuple[float, float]:
    """(intercept s, slope s/frame) of the least-squares line through the runs."""
    slope, intercept = np.polyfit(np.array(frames, float), np.array(seconds, float), 1)
    return float(intercept), float(slope)


def run(quick: bool = False) -> dict:
    matcher = create_matcher("effnet", layer="blocks.3", img_size=224)
    sizes = QUICK_SIZES if quick else SIZES
    framesets = {n: procedural(n, FRAMES_PER_EPISODE) for n in sizes}
    seconds: dict[str, dict[int, float]] = {s: {} for s in SETUPS}
    busy: dict[str, dict[int, float]] = {s: {} for s in SETUPS}  # cores kept busy: CPU seconds / wall seconds
    with tempfile.TemporaryDirectory() as tmp:
        clients, startup = start_clients(matcher, framesets[sizes[0]])
        try:
            with tempfile.TemporaryDirectory() as warm:  # in-process cold run: imports and builds the matcher here
                score_to_file(framesets[sizes[0]].root, matcher, out=warm, run=RunOptions(workers=1, progress=False))
            for n in sizes:
                for setup in SETUPS:
                    out = Path(tmp) / f"{setup}-{n}".replace(" ", "_")
                    c0, t0 = cpu_seconds(), time.perf_counter()
                    score_to_file(framesets[n].root, matcher, out=out,
                                  run=RunOptions(workers=1, progress=False, client=clients.get(setup)))
                    wall = time.perf_counter() - t0
                    seconds[setup][n], busy[setup][n] = round(wall, 3), round((cpu_seconds() - c0) / wall, 2)
                    print(f"  {setup:<24} {n:5d} frames {seconds[setup][n]:8.2f} s, {busy[setup][n]:.2f} cores busy",
                          flush=True)
        finally:
            for client in clients.values():
                client.close()
    lines = {s: fit(list(sizes), [seconds[s][n] for n in sizes]) for s in SETUPS}
    big = sizes[-1]
    overhead = seconds["1 worker"][big] / seconds["in-process"][big] - 1
    scaling = seconds["1 single-thread worker"][big] / seconds["2 single-thread workers"][big]
    print(f"\n{matcher.id}, {FRAMES_PER_EPISODE} frames per episode; wall seconds = fixed + per-frame x frames:")
    print(f"{'setup':<24} {'fixed s':>8} {'ms/frame':>9} {'frames/s':>9}  " +
          "  ".join(f"{n} frames" for n in sizes) + f"  cores busy at {big}   start-up s, cold first run s")
    for setup in SETUPS:
        intercept, slope = lines[setup]
        extra = startup.get(setup, {})
        print(f"{setup:<24} {intercept:8.2f} {1000 * slope:9.1f} {1 / slope:9.2f}  " +
              "  ".join(f"{seconds[setup][n]:>{len(str(n)) + 7}.2f}" for n in sizes) +
              f"  {busy[setup][big]:>{len(str(big)) + 12}.2f}" +
              (f"   {extra['start_s']:.2f}, {extra['cold_run_s']:.2f}" if extra else ""))
    print(f"1 worker vs in-process at {big} frames: wall {100 * overhead:+.1f} % "
          f"(target <= +10 %: {'holds' if overhead <= 0.10 else 'does not hold'})")
    ceiling = (os.cpu_count() or 1) / busy["1 single-thread worker"][big]
    print(f"2 single-thread workers vs 1 at {big} frames: x{scaling:.2f} "
          f"(target >= x1.7: {'holds' if scaling >= 1.7 else 'does not hold'}); one single-thread worker keeps "
          f"{busy['1 single-thread worker'][big]:.2f} cores busy, so {os.cpu_count()} cores allow at most "
          f"x{ceiling:.2f}")
    return dict(matcher=matcher.id, frames_per_episode=FRAMES_PER_EPISODE, sizes=list(sizes), seconds=seconds,
                fixed_s={s: round(lines[s][0], 3) for s in SETUPS},
                per_frame_s={s: round(lines[s][1], 5) for s in SETUPS}, cores_busy=busy, startup=startup,
                overhead_1_worker_at_largest=round(overhead, 4), scaling_2_over_1_single_thread=round(scaling, 3),
                scaling_ceiling=round(ceiling, 3))


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
