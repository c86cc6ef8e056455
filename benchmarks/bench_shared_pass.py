"""verify and effnet scored together in one pass against each alone: what one pass per frame saves, side by side.

Figures (docs/performance.md): wall seconds of whole scoring runs (the engine from decoding to
the table, a fresh cache each run) on the real-photo frame-set's first episodes, for ``effnet``
alone, ``verify`` alone, both scored one after the other, and both in one pass (``score_many``:
each frame decoded once, ``verify``'s locate map reused as ``effnet``'s scores); interleaved,
the fastest of the repeats, each as a multiple of ``effnet`` alone. Target: together at most
1.6x effnet alone.

``python -m benchmarks.bench_shared_pass [--quick]``.
"""

from __future__ import annotations

import tempfile

from benchmarks.framesets import real_photos
from benchmarks.timing import fastest
from pin_match.data.frameset import FrameSet
from pin_match.scoring import RunOptions, score_many

TARGET_RATIO = 1.6


def _first_episodes(fs: FrameSet, n: int) -> FrameSet:
    """The frame-set cut to its first ``n`` episodes of the val split, a view scored like any other."""
    part = fs.split("val")
    keep = set(part.episodes.episode_id[:n])
    part.episodes = part.episodes[part.episodes.episode_id.isin(keep)].reset_index(drop=True)
    part.frames = part.frames[part.frames.episode_id.isin(keep)].reset_index(drop=True)
    return part


def _scored(fs: FrameSet, groups: list[list[str]]) -> None:
    """Each group of matchers in one pass, into a fresh cache."""
    with tempfile.TemporaryDirectory() as tmp:
        for names in groups:
            score_many(fs, names, out=tmp, run=RunOptions(progress=False))


def run(quick: bool = False) -> dict:
    fs = _first_episodes(real_photos(), 1 if quick else 3)
    _scored(fs, [["effnet"], ["verify"]])  # warm-up: weights loaded, first-call allocations done
    sides = {"effnet alone": [["effnet"]], "verify alone": [["verify"]],
             "verify, then effnet": [["verify"], ["effnet"]], "verify + effnet, one pass": [["verify", "effnet"]]}
    best = fastest({name: (lambda g=groups: _scored(fs, g)) for name, groups in sides.items()}, 1 if quick else 3)
    n, base = len(fs.frames), best["effnet alone"].wall_s
    print(f"scoring runs on {n} real-photo frames, fastest of interleaved runs (target one pass / effnet alone "
          f"<= {TARGET_RATIO:g}):")
    print(f"{'run':<28} {'s':>7} {'s/frame':>8} {'x effnet':>9}")
    out = {}
    for name, t in best.items():
        out[name] = dict(wall_s=round(t.wall_s, 2), s_per_frame=round(t.wall_s / n, 4),
                         x_effnet=round(t.wall_s / base, 3))
        print(f"{name:<28} {t.wall_s:7.1f} {t.wall_s / n:8.3f} {t.wall_s / base:9.2f}")
    out["frames"] = n
    out["target_holds"] = out["verify + effnet, one pass"]["x_effnet"] <= TARGET_RATIO
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
