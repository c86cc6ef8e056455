"""The sigmas shipped for the demo apply to the demo sets as built now: a newcomer's demo scores val frames only.

When a change to a demo set's builder or to one of its matchers' ids makes them stale, the demo
still runs (it tunes on the train split again, minutes longer) and this test says what to redo.
"""

from __future__ import annotations

import pytest

from pin_match.evaluation.flows.demo import DEMO_SETS, shipped_sigmas
from pin_match.scoring.options import RunOptions

REDO = ("rerun `pin-match demo --tune --out DIR` and copy DIR/{folder}demo_sigmas.json to "
        "pin_match/evaluation/flows/demo_sigmas/{file}")


@pytest.mark.slow
@pytest.mark.parametrize("demo_set", DEMO_SETS, ids=lambda s: s.sigmas)
def test_the_shipped_sigmas_were_tuned_on_this_set_for_these_matchers(demo_set, tmp_path):
    redo = REDO.format(folder=f"{demo_set.folder}/" if demo_set.folder else "", file=demo_set.sigmas)
    assert demo_set.shipped.is_file(), redo
    fs = demo_set.build(tmp_path / "frameset", 0, RunOptions(workers=2, progress=False))
    assert shipped_sigmas(demo_set, fs) == demo_set.shipped, redo
