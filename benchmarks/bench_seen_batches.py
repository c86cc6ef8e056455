"""A house's walk read by each of its episodes: scoring with the crop batches a matcher keeps (``SeenBatches``)
against scoring with none kept, side by side.

``python -m benchmarks --only bench_seen_batches``. An exploration set's three episodes a house read the
same frames for three targets; the patch matchers' crop features are computed on the first and found again
on the other two. Both sides score the same set with the same matcher from a fresh cache, one after the other
on a quiet machine, and must give the same scores bit for bit.
"""

from __future__ import annotations

import numpy as np

from benchmarks.framesets import synthetic
from benchmarks.timing import fastest
from pin_match import create_matcher
from pin_match.matchers.common.patch import SeenBatches
from pin_match.scoring import RunOptions, score


def _matcher(name: str, keep: bool):
    matcher = create_matcher(name)
    if not keep:  # the locate pass is the patch matcher whose crops repeat; verify's is its ``locator``
        (getattr(matcher, "locator", None) or matcher)._seen = SeenBatches(budget=0)
    return matcher


def run(quick: bool) -> dict:
    """Seconds per side, their ratio and the frames scored (6 episodes in 2 houses: 3 episodes read each walk)."""
    import tempfile

    fs = synthetic("seen_batches_quick" if quick else "seen_batches", episodes=6, objects_per_family=3,
                   frames_per_episode=8 if quick else 32)
    options = RunOptions(workers=2, progress=False)
    tables = {}
    out = {}
    for name in ("verify", "effnet"):
        def side(keep: bool, name: str = name):
            with tempfile.TemporaryDirectory() as tmp:
                tables[keep] = score(fs, _matcher(name, keep), out=tmp, run=options)

        times = fastest({"kept": lambda: side(True), "none kept": lambda: side(False)})
        same = np.array_equal(tables[True].frames.score.to_numpy(), tables[False].frames.score.to_numpy())
        out[name] = dict(kept_s=times["kept"].wall_s, none_kept_s=times["none kept"].wall_s,
                         speedup=times["none kept"].wall_s / times["kept"].wall_s, same_scores=bool(same))
        print(f"{name}: {len(fs.frames)} frames, batches kept {times['kept'].wall_s:.1f} s, none kept "
              f"{times['none kept'].wall_s:.1f} s ({out[name]['speedup']:.2f}x), same scores: {same}")
    return dict(frames=len(fs.frames), episodes=len(fs.episodes), **out)
