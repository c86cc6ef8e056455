"""``verify``'s second zoom on every frame against on frames at its floor only, same frames, side by side.

Issue 73: the second zoom (step 5 of ``matchers/verify.py``) moves the first point and no score, and an agent
only walks to a goal's point, a frame at or above sigma; ``refine_floor`` (default 0.25, under every sigma
tuned for ``verify``) runs it only there. Both sides are whole scoring runs (the engine from decoding to the
table, a fresh cache each run), interleaved, the fastest of the repeats: ``refine_floor=0`` (every frame,
version 2's points) and the default. Frames: the demo's scanned set, its val split (built once into the
benchmarks' cache by the demo's own builder), cut to its first episodes. Beside the times, what the floor
changed: the largest score difference (0 expected), the frames at or above the floor whose points differ (0
expected) and the share of frames under it.

``python -m benchmarks.bench_refine_floor [--quick]``.
"""

from __future__ import annotations

import tempfile

import numpy as np

from benchmarks.bench_network_share import val_episodes
from benchmarks.framesets import demo_scanned
from benchmarks.loadavg import load_1min
from benchmarks.timing import fastest
from pin_match.data.frameset import FrameSet
from pin_match.matchers.verify import DEFAULT_REFINE_FLOOR
from pin_match.scoring import RunOptions, ScoreTable, score

QUIET = RunOptions(progress=False)
SIDES = {"second zoom on every frame": {"refine_floor": 0.0}, "second zoom at the floor": {}}


def _scored(fs: FrameSet, overrides: dict) -> ScoreTable:
    with tempfile.TemporaryDirectory() as tmp:
        return score(fs, "verify", overrides=overrides, out=tmp, run=QUIET)


def changed(every: ScoreTable, gated: ScoreTable, floor: float) -> dict:
    """What the floor changed: the largest score difference, and the frames at or above it whose points moved."""
    a, b = (t.frames.set_index(["episode_id", "frame_id"]).sort_index() for t in (every, gated))
    above = a.score.to_numpy() >= floor
    moved = [not (np.array_equal(x, y) and np.array_equal(u, v))
             for x, y, u, v in zip(a.points_x[above], b.points_x[above], a.points_y[above], b.points_y[above])]
    return dict(max_score_difference=float(np.abs(a.score.to_numpy() - b.score.to_numpy()).max()),
                frames_above_floor=int(above.sum()), frames_above_with_other_points=int(sum(moved)),
                share_under_floor=round(float(1 - above.mean()), 3))


def run(quick: bool = False) -> dict:
    fs = val_episodes(demo_scanned(), 1 if quick else 3)
    tables = {name: _scored(fs, overrides) for name, overrides in SIDES.items()}  # warm-up, and the tables compared
    before = load_1min()
    best = fastest({name: (lambda o=overrides: _scored(fs, o)) for name, overrides in SIDES.items()},
                   1 if quick else 2)
    base = best["second zoom on every frame"].wall_s
    out = dict(frames=len(fs.frames), floor=DEFAULT_REFINE_FLOOR,
               seconds={k: round(t.wall_s, 2) for k, t in best.items()},
               ratio=round(best["second zoom at the floor"].wall_s / base, 3),
               **changed(*tables.values(), DEFAULT_REFINE_FLOOR), load={"before": before, "after": load_1min()})
    print(f"verify on {out['frames']} frame-target pairs of the demo's scanned val split, fastest of interleaved "
          f"whole scoring runs: " + ", ".join(f"{k} {v:.1f} s" for k, v in out["seconds"].items())
          + f" ({out['ratio']:.2f}x); {out['share_under_floor']:.0%} of frames under the floor "
          f"{DEFAULT_REFINE_FLOOR}; largest score difference {out['max_score_difference']:.1e}; frames at the floor "
          f"with other points {out['frames_above_with_other_points']} of {out['frames_above_floor']}; load "
          f"{out['load']['before']} -> {out['load']['after']}")
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
