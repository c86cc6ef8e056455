"""The one timing loop of the benchmarks, and the two measurements built on it (a matcher per frame, a score run).

Every figure is the fastest of interleaved runs: load from other jobs only ever adds time,
so the fastest run is the nearest to the work's own cost, and alternating the sides keeps a
burst of load from landing on one side only. CPU seconds (this process, all its threads)
come beside wall seconds because a shared machine's wall time may be mostly the wait for a core.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from pin_match import Target, create_matcher
from pin_match.contract import Matcher
from pin_match.data.frameset import FrameSet
from pin_match.scoring import RunOptions, ScoreTable, score


@dataclass(frozen=True)
class Timing:
    wall_s: float
    cpu_s: float


def fastest(sides: Mapping[str, Callable[[], object]], repeats: int = 1) -> dict[str, Timing]:
    """Each side called ``repeats`` times, the sides interleaved; per side its fastest run and that run's CPU time."""
    best: dict[str, Timing] = {}
    for _ in range(repeats):
        for name, fn in sides.items():
            wall, cpu = time.perf_counter(), time.process_time()
            fn()
            run = Timing(time.perf_counter() - wall, time.process_time() - cpu)
            if name not in best or run.wall_s < best[name].wall_s:
                best[name] = run
    return best


def once(fn: Callable[[], object]) -> Timing:
    """One call of ``fn``, timed."""
    return fastest({"once": fn})["once"]


@dataclass(frozen=True)
class FrameTiming:
    prepare_s: float
    per_frame: Timing
    frames: int


def time_frames(matcher: Matcher, target: Target, images: list[np.ndarray],
                after_warmup: Callable[[], None] = lambda: None) -> FrameTiming:
    """``matcher.prepare(target)``, then ``match`` per frame over ``images[1:]`` after ``images[0]`` as warm-up."""
    prepare = once(lambda: matcher.prepare(target))
    matcher.match(images[0])
    after_warmup()
    frames = images[1:]
    run = once(lambda: [matcher.match(image) for image in frames])
    return FrameTiming(prepare.wall_s, Timing(run.wall_s / len(frames), run.cpu_s / len(frames)), len(frames))


def timed_score(fs: FrameSet, matcher: str | Matcher, workers: int) -> tuple[ScoreTable, float]:
    """One ``score`` run into a fresh cache, the whole engine from decoding to the table; its wall seconds."""
    got: dict[str, ScoreTable] = {}
    with tempfile.TemporaryDirectory() as tmp:
        options = RunOptions(workers=workers, progress=False)
        timing = once(lambda: got.update(table=score(fs, matcher, out=tmp, run=options)))
    return got["table"], timing.wall_s


def bench_inputs(quick: bool) -> tuple[Target, list[np.ndarray]]:
    """A PIN-sized target (1280x960 RGBA references: a textured disc, so keypoint detectors find the object)
    and random 640x360 frames: one warm-up plus 1 (quick) or 3 timed."""
    rng = np.random.default_rng(1)
    view = np.zeros((1280, 960, 4), np.uint8)
    yy, xx = np.mgrid[:1280, :960]
    view[..., :3] = rng.integers(0, 256, (1280, 960, 3), dtype=np.uint8)
    view[(yy - 640) ** 2 + (xx - 480) ** 2 < 350 ** 2, 3] = 255
    target = Target("bench", "mug", (view, view, view),
                    ("a red ceramic mug with a white handle", "a mug on the kitchen table", "a red cup"))
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (640, 360, 3), dtype=np.uint8) for _ in range(2 if quick else 4)]
    return target, images


def time_matchers(options: dict[str, dict], target: Target, images: list[np.ndarray]) -> dict[str, dict]:
    """``options`` maps a matcher name to its config overrides; ``images[0]`` is the warm-up frame."""
    out = {}
    for name, kwargs in options.items():
        t = time_frames(create_matcher(name, **kwargs), target, images)
        out[name] = {"ms_per_frame": round(1000 * t.per_frame.wall_s, 1), "prepare_s": round(t.prepare_s, 2),
                     "frames": t.frames, "threads": torch.get_num_threads()}
    print(f"{'matcher':<10} {'ms/frame':>10} {'prepare s':>10} {'frames':>7}")
    for name, row in out.items():
        print(f"{name:<10} {row['ms_per_frame']:>10.1f} {row['prepare_s']:>10.2f} {row['frames']:>7}")
    return out


def time_random_models(save: Callable[[Path], Mapping[str, Path]],
                       options: Callable[[dict[str, str]], dict[str, dict]], quick: bool) -> dict[str, dict]:
    """``time_matchers`` on models with random weights: ``save(folder)`` writes them (torch seeded 0 first) and
    returns each one's folder by key; ``options`` maps those folders to each matcher's config overrides."""
    target, images = bench_inputs(quick)
    with tempfile.TemporaryDirectory() as tmp:
        torch.manual_seed(0)
        paths = {key: str(path) for key, path in save(Path(tmp)).items()}
        return time_matchers(options(paths), target, images)
