"""Reading a score table from the cache folder a scoring run leaves, as every command may be given."""

from __future__ import annotations

import pandas as pd
import pytest

from pin_match.scoring.table import ScoreTable, ScoreTableError


def _table(score: float) -> ScoreTable:
    row = dict(frame_id="f0", episode_id="e0", step=0, split="val", score=score, crop_scores=[score],
               points_x=[1.0], points_y=[2.0], point_scores=[score])
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
