"""A house's walk read by each of its episodes: scoring with the crop batches a matcher keeps (``SeenBatches``)
against scoring with none kept, side by side.

``python -m benchmarks --only bench_seen_batches``. An exploration set's three episodes a house read the
same frames for three targets; the patch matchers' crop features are computed on the first and found again
on the other two. The sides score the same set with the same matcher from a fresh cache, one after the other
on a quiet machine, and must give the same scores bit for bit: ``REMEMBERED_BYTES`` kept, the 384 MB kept
before issue 73 (a walk of 120 frames), and none. The set is the demo's scanned val split, one house's whole
tour (303 frames) read by 3 episodes; ``--quick``: 8-frame walks.
"""

from __future__ import annotations

import numpy as np

from benchmarks.framesets import demo_scanned, synthetic
from benchmarks.timing import fastest
from pin_match import create_matcher
from pin_match.matchers.common.patch import REMEMBERED_BYTES, SeenBatches
from pin_match.scoring import RunOptions, score

BUDGETS = {"a tour kept": REMEMBERED_BYTES, "384 MB kept (before)": 384 * 2**20, "none kept": 0}


def _matcher(name: str, budget: int):
    matcher = create_matcher(name)
    # the locate pass is the patch matcher whose crops repeat; verify's is its ``locator``
    (getattr(matcher, "locator", None) or matcher)._seen = SeenBatches(budget=budget)
    return matcher


def run(quick: bool) -> dict:
    """Seconds per side, each as a multiple of the first's, and the frames scored."""
    import tempfile

    fs = synthetic("seen_batches_quick", episodes=6, objects_per_family=3, frames_per_episode=8) if quick \
        else demo_scanned()
    options = RunOptions(workers=2, progress=False)
    out = {}
    for name in ("verify", "effnet"):
        tables = {}

        def side(label: str, name: str = name, tables: dict = tables):
            with tempfile.TemporaryDirectory() as tmp:
                tables[label] = score(fs, _matcher(name, BUDGETS[label]), out=tmp, run=options)

        times = fastest({label: (lambda label=label: side(label)) for label in BUDGETS})
        first = next(iter(BUDGETS))
        same = all(np.array_equal(tables[first].frames.score.to_numpy(), t.frames.score.to_numpy())
                   for t in tables.values())
        out[name] = dict(seconds={k: round(t.wall_s, 2) for k, t in times.items()},
                         ratio={k: round(t.wall_s / times[first].wall_s, 3) for k, t in times.items()},
                         same_scores=bool(same))
        print(f"{name}: {len(fs.frames)} frames, " + ", ".join(
            f"{k} {t.wall_s:.1f} s ({t.wall_s / times[first].wall_s:.2f}x)" for k, t in times.items())
            + f"; same scores: {same}")
    return dict(frames=len(fs.frames), episodes=len(fs.episodes), **out)
