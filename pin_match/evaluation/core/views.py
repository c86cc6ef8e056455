"""Which reference view the matcher's best box matched: the frontal view, the back or the top.

A PIN agent meets its target from any side; a matcher that compares each box with one
reference view at a time names the view it matched best (``MatchResult.box_views``), and the
score table keeps the best box's (``view``; ``NO_VIEW`` where the matcher named none). Counted
here per view: the matched frames showing the target, those showing only a look-alike, and
every target frame (matched or not), so a report says whether targets seen from behind are
found by their back view and whether false alarms come from one view. Pure functions: tables
in, numbers out.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pin_match.contract.results import NO_VIEW, VIEW_NAMES
from pin_match.evaluation.core.labels import CM, TM, frame_classes
from pin_match.scoring.table import ScoreTable, require_columns

NONE_NAMED = "none named"  # the row of frames whose best box named no view (or that had no box)
VIEW_COLUMNS = ("tm_matched", "cm_matched", "target_frames")
HEADERS = dict(tm_matched="matched, target (TM)", cm_matched="matched, look-alike only (CM)",
               target_frames="target frames (best box's view)")


def best_views(table: ScoreTable) -> pd.Series:
    """Per frame id, the view its best box matched (``NO_VIEW``: none named); a table without the column is refused,
    naming it."""
    require_columns(table.frames, f"score table of {table.matcher_id}", ("view",))
    return pd.Series(table.frames.view.to_numpy(np.int64), index=table.frames.frame_id.to_numpy())


def view_table(scored: pd.DataFrame, table: ScoreTable, sigma: float) -> pd.DataFrame | None:
    """Per view (rows ``VIEW_NAMES``, then ``NONE_NAMED``), of the scored frames (``EvalContext.scored``): the frames
    matched at ``sigma`` that show the target (TM), those that show only a same-category look-alike (CM), and the
    frames showing the target, matched or not, whose best box matched that view. None when ``table`` names no view
    for any of the scored frames (a matcher without box views)."""
    view = scored.frame_id.map(best_views(table)).fillna(NO_VIEW).to_numpy(np.int64)
    if not (view != NO_VIEW).any():
        return None
    cls = frame_classes(scored)
    matched = scored.score.to_numpy(np.float64) >= sigma
    rows = {}
    for k, name in [*enumerate(VIEW_NAMES), (NO_VIEW, NONE_NAMED)]:
        on = view == k
        rows[name] = dict(tm_matched=int((on & matched & (cls == TM)).sum()),
                          cm_matched=int((on & matched & (cls == CM)).sum()),
                          target_frames=int((on & (cls == TM)).sum()))
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("view")[list(VIEW_COLUMNS)]


def readable(table: pd.DataFrame) -> pd.DataFrame:
    """``view_table``'s columns under the headers a person reads."""
    return table[list(VIEW_COLUMNS)].rename(columns=HEADERS)
