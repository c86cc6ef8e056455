"""Reading a score table from the cache folder a scoring run leaves, as every command may be given; what a row keeps of
a matcher's result."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pin_match.contract.results import NO_VIEW, MatchResult
from pin_match.scoring.schema import COLUMNS, episode_rows
from pin_match.scoring.table import ScoreTable, ScoreTableError


def _table(score: float) -> ScoreTable:
    row = dict(frame_id="f0", episode_id="e0", step=0, split="val", score=score, crop_scores=[score],
               points_x=[1.0], points_y=[2.0], point_scores=[score], view=-1)
    return ScoreTable(pd.DataFrame([row]), dict(matcher="m", matcher_id="m@1"))


def test_folder_reads_the_merged_table_else_the_only_one(tmp_path):
    _table(0.25).write(tmp_path / "scores_val.parquet")
    assert ScoreTable.read(tmp_path).frames.score.tolist() == [0.25]
    _table(0.75).write(tmp_path / "scores_train.parquet")
    with pytest.raises(ScoreTableError, match=r"holds 2 score tables \(scores_train.parquet, scores_val.parquet\)"):
        ScoreTable.read(tmp_path)
    _table(0.5).write(tmp_path / "scores_all.parquet")
    assert ScoreTable.read(tmp_path).frames.score.tolist() == [0.5]
    (tmp_path / "empty").mkdir()
    with pytest.raises(ScoreTableError, match=r"no score table \(scores\*\.parquet\) in .*empty"):
        ScoreTable.read(tmp_path / "empty")


def test_non_finite_score_is_refused_naming_the_frame(tmp_path):
    _table(float("nan")).write(tmp_path / "scores_all.parquet")
    with pytest.raises(ScoreTableError, match=r"scores_all.parquet: frame 'f0' has a non-finite score nan"):
        ScoreTable.read(tmp_path)


def _boxed(box_scores: list[float], views: list[int] | None) -> MatchResult:
    boxes = np.tile(np.array([[0.0, 0.0, 4.0, 4.0]], np.float32), (len(box_scores), 1))
    return MatchResult(score=max(box_scores, default=0.0), boxes=boxes, box_scores=np.array(box_scores, np.float32),
                       box_views=None if views is None else np.array(views, np.int64))


def test_a_row_keeps_the_view_its_best_box_matched():
    """Issue 51.4: the view of the highest-scoring box, the first among equals; -1 where the matcher named none."""
    results = [_boxed([0.2, 0.9, 0.5], [2, 1, 0]),  # the best box is the second: back
               _boxed([0.7, 0.3, 0.7], [2, 0, 1]),  # a tie between the first and the third: the first's, top
               _boxed([0.4, 0.8], None),            # boxes without views
               _boxed([], []),                      # no box at all
               MatchResult(score=0.6)]              # a matcher without boxes
    rows = episode_rows("e0", "val", [f"f{k}" for k in range(5)], np.arange(5), results)
    assert list(rows.columns) == COLUMNS and rows.view.dtype == np.int64
    assert rows.view.tolist() == [1, 2, NO_VIEW, NO_VIEW, NO_VIEW] == [r.best_view() for r in results]


def test_a_table_without_the_view_column_is_refused_naming_it(tmp_path):
    """A table built by hand, or written before the column existed, is named with what it lacks."""
    import pyarrow.parquet as pq

    table = _table(0.5)
    table.frames = table.frames.drop(columns="view")
    with pytest.raises(ScoreTableError, match=r"^score table of m@1 lacks columns \['view'\]$"):
        table.write(tmp_path / "scores_all.parquet")
    _table(0.5).write(tmp_path / "scores_all.parquet")
    whole = pq.read_table(tmp_path / "scores_all.parquet")
    (tmp_path / "old").mkdir()
    pq.write_table(whole.drop_columns(["view"]).replace_schema_metadata(whole.schema.metadata),
                   tmp_path / "old" / "scores_all.parquet")
    with pytest.raises(ScoreTableError, match=r"old/scores_all\.parquet lacks columns \['view'\]$"):
        ScoreTable.read(tmp_path / "old")
