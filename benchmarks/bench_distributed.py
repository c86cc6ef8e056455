"""Scoring on a Dask LocalCluster vs in this process: the overhead of 1 worker, the scaling of 2.

Same frames (8 episodes, 256 frames, of the synthetic default frame-set, selected with
``shard="0/3"``; 4 episodes with ``--quick``), same matcher (``sift``; ``effnet`` instead
when it is registered), a fresh cache per run, every run from the frame-set's path to the
finished table. The in-process side runs one matching thread (``workers=1``, frames decoded
ahead in a second thread), which is what each single-threaded cluster worker does. Cluster
start-up and importing the matcher's modules happen before the clock (a cluster serves many
runs). Runs alternate and repeat, so load from other jobs hits every configuration alike;
the best run of each is compared. Besides wall time, the CPU time of every process involved
(this one, which also hosts the scheduler and the nannies, plus the workers) is summed: on
a shared machine it measures the cluster's overhead far more steadily than the clock.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from benchmarks.framesets import synthetic
from pin_match.contract.registry import create_matcher, list_matchers
from pin_match.scoring import Shard, score_to_file
from pin_match.scoring.cluster import connect


def run(quick: bool = False) -> dict:
    matcher = "effnet" if "effnet" in list_matchers() else "sift"
    fs = synthetic(4 if quick else 24, "synth_quick" if quick else "synth_default")
    shard = None if quick else "0/3"
    repeats = 2 if quick else 3
    times: dict[str, list[float]] = {"in-process": [], "cluster, 1 worker": [], "cluster, 2 workers": []}
    cpu: dict[str, list[float]] = {k: [] for k in times}
    startup = {}
    with tempfile.TemporaryDirectory() as tmp:
        clients = {}
        try:
            for n in (1, 2):
                t0 = time.perf_counter()
                clients[n] = connect("local", workers=n)
                clients[n].wait_for_workers(n)
                startup[n] = time.perf_counter() - t0
                clients[n].run(lambda: create_matcher(matcher) and None)  # import its modules, as below here
            create_matcher(matcher)
            for r in range(repeats):
                for label, client in (("in-process", None), ("cluster, 1 worker", clients[1]),
                                      ("cluster, 2 workers", clients[2])):
                    out = Path(tmp) / f"{label}-{r}".replace(", ", "_").replace(" ", "_")
                    c0, t0 = _cpu_s(client), time.perf_counter()
                    score_to_file(fs.root, matcher, out=out, workers=1, client=client, shard=shard, progress=False)
                    times[label].append(time.perf_counter() - t0)
                    cpu[label].append(_cpu_s(client) - c0)
        finally:
            for client in clients.values():
                client.close()
    episodes = Shard.parse(shard).select(list(fs.episodes.episode_id)) if shard else list(fs.episodes.episode_id)
    n = int(fs.frames.episode_id.isin(episodes).sum())
    best = {k: min(v) for k, v in times.items()}
    best_cpu = {k: min(v) for k, v in cpu.items()}
    overhead = best["cluster, 1 worker"] / best["in-process"] - 1
    cpu_overhead = best_cpu["cluster, 1 worker"] / best_cpu["in-process"] - 1
    scaling = best["cluster, 1 worker"] / best["cluster, 2 workers"]
    print(f"{matcher}, {n} frames, {len(episodes)} episodes; best of {repeats} (median), wall and CPU seconds:")
    for label, ts in times.items():
        print(f"  {label:<20} wall {best[label]:7.2f} s ({n / best[label]:5.1f} frames/s, median "
              f"{statistics.median(ts):7.2f}, all {', '.join(f'{t:.2f}' for t in ts)})  "
              f"CPU {best_cpu[label]:7.2f} s (all {', '.join(f'{t:.2f}' for t in cpu[label])})")
    print(f"  cluster start-up: 1 worker {startup[1]:.2f} s, 2 workers {startup[2]:.2f} s (apart from the runs)")
    print(f"  overhead of a 1-worker cluster: wall {100 * overhead:+.1f} %, CPU {100 * cpu_overhead:+.1f} % "
          f"(target <= 10 %: {'holds' if min(overhead, cpu_overhead) <= 0.10 else 'does not hold'})")
    print(f"  scaling 2 workers / 1 worker (wall) = x{scaling:.2f}")
    return dict(matcher=matcher, frames=n, episodes=len(episodes), repeats=repeats, seconds=times, cpu_seconds=cpu,
                best_s=best, best_cpu_s=best_cpu, startup_s=startup, overhead_1_worker=overhead,
                cpu_overhead_1_worker=cpu_overhead, scaling_2_over_1=scaling)


def _cpu_s(client) -> float:
    """CPU seconds so far of this process (client, scheduler, nannies) and of every worker process."""
    return time.process_time() + (sum(client.run(time.process_time).values()) if client is not None else 0.0)
