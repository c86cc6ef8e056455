"""Frame-sets for benchmarks, each built once by the library's own builders and loaded from its cache folder after."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from pin_match.data.frameset import MANIFEST, FrameSet
from pin_match.data.synth.size import SynthSize
from pin_match.data.writer import FrameSetWriter

CACHE = Path("pin_match_runs") / "benchmarks"


def cached(root: Path, build: Callable[[Path], FrameSet],
           current: Callable[[FrameSet], bool] = lambda fs: True) -> FrameSet:
    """The frame-set at ``root``, built there by ``build(root)`` when it has none yet or the one there is not
    ``current`` (a synthetic set of other sizes or of another definition of its houses): every benchmark's one way
    in."""
    if (root / MANIFEST).exists():
        fs = FrameSet.load(root)
        if current(fs):
            return fs
        shutil.rmtree(root)
    return build(root)


def made_as(fs: FrameSet, size: SynthSize) -> bool:
    """Was ``fs`` generated at ``size`` by this install's definition of a house (``generator.definition``)?"""
    from pin_match.data.synth.generator import definition
    from pin_match.data.synth.scans import ScanFolder

    made = fs.manifest.get("provenance") or {}
    return made.get("definition") == definition(ScanFolder.open()) and all(
        made.get(k) == getattr(size, k) for k in ("seed", "episodes", "objects_per_family", "frames_per_episode",
                                                  "walk", "rooms"))


def synthetic(name: str, **settings) -> FrameSet:
    """A cached synthetic frame-set from ``pin-match generate``'s builder; ``settings`` are its keywords."""
    from pin_match.data.synth import generate

    size = SynthSize(**settings)
    return cached(CACHE / name, lambda root: generate(root, size, overwrite=True), lambda fs: made_as(fs, size))


def demo_scanned() -> FrameSet:
    """The demo's scanned set, its val split alone (one house's whole tour, read by 3 episodes), as ``pin-match
    demo`` renders it at shipped sigmas."""
    from pin_match.evaluation.flows.demo import SCANNED_SIZE, scanned
    from pin_match.scoring import RunOptions

    return cached(CACHE / "demo_scanned_val", lambda root: scanned(root, 0, RunOptions(progress=False), val_only=True),
                  lambda fs: made_as(fs, replace(SCANNED_SIZE, seed=0)))


def procedural(n_frames: int, frames_per_episode: int = 100, seed: int = 0) -> FrameSet:
    """Many cheap frames (coloured rectangles, one of them the target) for memory and throughput scaling."""
    name = f"procedural_{n_frames}" if frames_per_episode == 100 else f"procedural_{n_frames}_per{frames_per_episode}"
    return cached(CACHE / name, lambda root: _write_procedural(root, n_frames, frames_per_episode, seed))


def _write_procedural(root: Path, n_frames: int, frames_per_episode: int, seed: int) -> FrameSet:
    rng = np.random.default_rng(seed)
    w = FrameSetWriter(root, root.name, overwrite=True)
    view = np.zeros((96, 96, 4), np.uint8)
    view[16:80, 16:80] = (220, 60, 40, 255)
    w.add_object("box", "toy", "val", [view] * 3, ["a red box", "a red square box", "a small red box"])
    n_episodes = max(1, n_frames // frames_per_episode)
    for e in range(n_episodes):
        episode_id = f"ep{e:05d}"
        w.add_episode(episode_id, "val", "procedural", "box", [])
        for step in range(frames_per_episode):
            image = np.full((640, 360, 3), rng.integers(40, 200, 3), np.uint8)
            mask = np.zeros((640, 360), np.uint16)
            if step % 5 == 0:
                y, x = rng.integers(0, 560), rng.integers(0, 280)
                image[y:y + 64, x:x + 64] = (220, 60, 40)
                mask[y:y + 64, x:x + 64] = 1
            w.add_frame(episode_id, step, image, mask, {1: ("box", "target")})
    return w.close()


def real_photos(seed: int = 0) -> FrameSet:
    """The recolour frame-set (``pin-match data build recolour``; needs scikit-image), cached per seed."""
    from pin_match.data.sources.recolour import build

    name = "realset" if seed == 0 else f"realset_seed{seed}"
    return cached(CACHE / name, lambda root: build(root, seed=seed, overwrite=True))
