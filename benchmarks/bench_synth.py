"""Synthetic generator throughput: frames per second per core, reference renders, scaling 1 vs 2 workers.

Run directly (``python benchmarks/bench_synth.py [--quick]``) or through ``run(quick)``.
Timings are wall-clock on this machine; the generator's output is identical for both worker
counts (checked here by fingerprint), so the comparison is like for like.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from benchmarks.timing import once


def _time_frames(n: int) -> float:
    """Seconds per rendered frame of a house's walk and approach views (render + mask + camera effects + encoding),
    one process."""
    from pin_match.data.compose import stable_seed
    from pin_match.data.synth.generator import HousePlan, plan_houses, render_house
    from pin_match.data.synth.objects import make_objects
    from pin_match.data.synth.scans import ScanFolder

    specs = make_objects(ScanFolder.open(), 4)
    house_id, split, objs, episodes = plan_houses(specs, 0, 2)[0]
    with tempfile.TemporaryDirectory() as tmp:
        plan = HousePlan(house_id, split, stable_seed(0, "scene", house_id), stable_seed(0, "house", house_id),
                         tuple(objs), tuple(episodes[:1]), n, "explore", tmp)
        render_house(plan)  # warm-up: first pybullet connection
        frames: dict = {}
        timing = once(lambda: frames.update(n=len(render_house(plan)[0][1])))
        return timing.wall_s / frames["n"]


def _time_references(n: int) -> float:
    from pin_match.data.synth.generator import render_object
    from pin_match.data.synth.objects import make_objects
    from pin_match.data.synth.scans import ScanFolder

    specs = make_objects(ScanFolder.open(), 2)[::2][:n]
    render_object(specs[0], seed=0)
    return once(lambda: [render_object(s, seed=0) for s in specs]).wall_s / len(specs)


def _time_generate(workers: int, settings: dict) -> tuple[float, str, int]:
    from pin_match.data.synth import SynthSize, generate

    got: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        seconds = once(lambda: got.update(fs=generate(Path(tmp) / "fs", SynthSize(**settings), workers=workers))).wall_s
        return seconds, got["fs"].fingerprint, len(got["fs"].frames)


def run(quick: bool) -> dict:
    """Measure and print; returns the numbers (seconds, frames/s) for a common runner."""
    settings = (dict(episodes=4, objects_per_family=4, frames_per_episode=8) if quick
                else dict(episodes=8, objects_per_family=4, frames_per_episode=32))
    per_frame = _time_frames(8 if quick else 32)
    per_object = _time_references(4 if quick else 12)
    t1, fp1, n_frames = _time_generate(1, settings)
    t2, fp2, _ = _time_generate(2, settings)
    result = dict(
        frame_ms_one_core=round(per_frame * 1000, 1), frames_per_s_per_core=round(1 / per_frame, 2),
        reference_object_ms_one_core=round(per_object * 1000, 1), generate_settings=settings, frames=n_frames,
        generate_s_1_worker=round(t1, 1), generate_s_2_workers=round(t2, 1), speedup_2_workers=round(t1 / t2, 2),
        identical_output=fp1 == fp2,
    )
    print(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    run(ap.parse_args().quick)
