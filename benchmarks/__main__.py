"""Run every benchmark and print its figures: ``python -m benchmarks [--quick] [--only NAME ...] [--json OUT]``.

Each module exposes ``run(quick) -> dict`` and prints its own table; the runner collects
the dicts (and the machine) into one JSON file for docs/performance.md. The 1-minute load
average before and after each benchmark is printed and stored with its figures; ``--json``
is refused when the load before any benchmark was above 1.5 (not a quiet machine), unless
``--noisy`` is given, which marks the file as noisy.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import sys
import time
import traceback

from benchmarks.loadavg import QUIET_LOAD, load_1min, refusal

MODULES = ("bench_pipeline", "bench_weight_free", "bench_sweep", "bench_synth", "bench_memory",
           "bench_model_matchers_a", "bench_model_matchers_b", "bench_distributed", "bench_training",
           "bench_glue_matchers", "bench_effnet", "bench_effnet_variants", "bench_verify", "bench_shared_pass",
           "bench_network_share", "bench_fold", "bench_seen_batches", "bench_zoom_batch",
           "bench_refine_floor")


def machine() -> dict:
    import torch

    return dict(python=platform.python_version(), platform=platform.platform(), cpus=os.cpu_count(),
                processor=platform.processor() or platform.machine(), torch=torch.__version__,
                torch_threads=torch.get_num_threads())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes: a smoke run, not figures to quote")
    p.add_argument("--only", nargs="+", choices=MODULES)
    p.add_argument("--json", help="write all results to this file")
    p.add_argument("--noisy", action="store_true",
                   help=f"write --json even when the load average before a benchmark was above {QUIET_LOAD:g}")
    a = p.parse_args(argv)
    results, failed, loads = {"machine": machine(), "quick": a.quick, "noisy": a.noisy}, [], {}
    print(json.dumps(results["machine"]))
    now = load_1min() if a.json and not a.noisy else 0.0
    if now > QUIET_LOAD:
        print(f"warning: load average {now:.2f} > {QUIET_LOAD:g} now; --json will be refused unless the "
              "machine is quiet before every benchmark", file=sys.stderr)
    for name in a.only or MODULES:
        print(f"\n=== {name} ===", flush=True)
        load = loads[name] = {"before": load_1min()}
        print(f"(load average before: {load['before']:.2f})", flush=True)
        t0 = time.perf_counter()
        try:
            results[name] = importlib.import_module(f"benchmarks.{name}").run(quick=a.quick)
        except Exception:  # one broken benchmark must not hide the others' figures
            traceback.print_exc()
            failed.append(name)
            continue
        finally:
            load["after"] = load_1min()
        results[name]["load_1min"] = load
        print(f"({name}: {time.perf_counter() - t0:.1f} s; load average before {load['before']:.2f}, "
              f"after {load['after']:.2f})", flush=True)
    results["load_1min"] = loads
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
    if a.json:
        why = refusal(loads, a.noisy)
        if why:
            print(f"\n{why}", file=sys.stderr)
            return 2
        from pin_match.atomic import write_json

        write_json(a.json, results)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
