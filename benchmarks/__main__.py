"""Run every benchmark and print its figures: ``python -m benchmarks [--quick] [--only NAME ...] [--json OUT]``.

Each module exposes ``run(quick) -> dict`` and prints its own table; the runner collects
the dicts (and the machine) into one JSON file for docs/performance.md.
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

MODULES = ("bench_pipeline", "bench_weight_free", "bench_sweep", "bench_synth", "bench_memory",
           "bench_model_matchers_a", "bench_model_matchers_b", "bench_distributed", "bench_training",
           "bench_glue_matchers", "bench_effnet")


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
    a = p.parse_args(argv)
    results, failed = {"machine": machine(), "quick": a.quick}, []
    print(json.dumps(results["machine"]))
    for name in a.only or MODULES:
        print(f"\n=== {name} ===", flush=True)
        t0 = time.perf_counter()
        try:
            results[name] = importlib.import_module(f"benchmarks.{name}").run(quick=a.quick)
        except Exception:  # one broken benchmark must not hide the others' figures
            traceback.print_exc()
            failed.append(name)
            continue
        print(f"({name}: {time.perf_counter() - t0:.1f} s)", flush=True)
    if a.json:
        from pin_match.atomic import write_json

        write_json(a.json, results)
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
