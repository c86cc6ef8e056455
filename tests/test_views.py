"""Which reference view the best box matched, counted per view on a hand-built scored table (issue 51.4)."""

from __future__ import annotations

import pandas as pd
import pytest

from pin_match.evaluation.core.views import NONE_NAMED, view_table
from pin_match.scoring.table import ScoreTable, ScoreTableError

SIGMA = 0.5
# frame: (shows the target, a same-category look-alike, another object; score; the view its best box matched)
FRAMES = {
    "f0": ((True, False, False), 0.9, 1),   # target, matched, back
    "f1": ((True, False, False), 0.8, 1),   # target, matched, back
    "f2": ((True, False, False), 0.2, 0),   # target, missed, frontal
    "f3": ((True, True, False), 0.7, 2),    # target beside a look-alike: a target frame, matched, top
    "f4": ((False, True, False), 0.6, 0),   # look-alike only, matched, frontal
    "f5": ((False, True, False), 0.4, 2),   # look-alike only, below sigma
    "f6": ((False, False, True), 0.9, 0),   # another object only: neither TM nor CM
    "f7": ((True, False, False), 0.5, -1),  # target at sigma exactly: matched, no view named
    "f8": ((False, True, False), 0.55, -1),  # look-alike only, matched, no view named
    "f9": ((False, False, False), 0.1, 2),  # nothing shown
}


def scored_and_table(views: dict[str, int] | None = None) -> tuple[pd.DataFrame, ScoreTable]:
    scored = pd.DataFrame([dict(frame_id=f, target_visible=t, same_visible=s, other_visible=o, score=score)
                           for f, ((t, s, o), score, _) in FRAMES.items()])
    view = [(views or {}).get(f, v) for f, (_, _, v) in FRAMES.items()]
    frames = pd.DataFrame(dict(frame_id=list(FRAMES), view=view))
    return scored, ScoreTable(frames, dict(matcher="hand", matcher_id="hand@0"))


def test_counts_per_view_by_hand():
    scored, table = scored_and_table()
    counts = view_table(scored, table, SIGMA)
    assert list(counts.index) == ["frontal", "back", "top", NONE_NAMED]
    assert counts.to_dict("index") == {
        "frontal": dict(tm_matched=0, cm_matched=1, target_frames=1),  # f4; f2
        "back": dict(tm_matched=2, cm_matched=0, target_frames=2),     # f0, f1
        "top": dict(tm_matched=1, cm_matched=0, target_frames=1),      # f3
        NONE_NAMED: dict(tm_matched=1, cm_matched=1, target_frames=1)}  # f7; f8
    # every matched target frame and every target frame counted once: the report's own TM count and target frames
    assert counts.tm_matched.sum() == 4 and counts.target_frames.sum() == 5


def test_a_matcher_naming_no_view_has_no_table_and_a_table_without_the_column_is_named():
    scored, table = scored_and_table({f: -1 for f in FRAMES})
    assert view_table(scored, table, SIGMA) is None
    bare = ScoreTable(table.frames.drop(columns="view"), table.meta)
    with pytest.raises(ScoreTableError, match=r"^score table of hand@0 lacks columns \['view'\]$"):
        view_table(scored, bare, SIGMA)
