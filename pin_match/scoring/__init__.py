"""Scoring: the one place where frame-sets meet matchers, into a cache keyed by matcher id and frame-set.

``score`` / ``score_to_file`` / ``score_many`` / ``run_jobs`` run episodes here (``local``) or on a Dask cluster
(``cluster``); both call ``episode.score_episode`` and write the same chunk files, so
either resumes the other. ``schema`` holds what a table and its chunks contain, the metadata
encoding and when a chunk counts (a damaged one is scored again); ``cache`` the folder rule,
finding and merging tables; ``table`` the ``ScoreTable`` every later step reads; ``options``
the ``RunOptions`` (batch size, workers, progress bars) that callers pass down as one object.
"""

from pin_match.scoring.api import run_jobs, score, score_many, score_to_file
from pin_match.scoring.cache import (
    Shard,
    ShardError,
    cache_dir,
    canonical_order,
    find_score_table,
    merge,
    read_meta,
    table_meta,
    table_name,
)
from pin_match.scoring.episode import PreparedMatchers, score_episode
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.product import SCORES, Job, Product
from pin_match.scoring.table import ScoreTable, ScoreTableError

__all__ = ["DEFAULT_RUN", "SCORES", "Job", "PreparedMatchers", "Product", "RunOptions", "ScoreTable",
           "ScoreTableError", "Shard", "ShardError", "cache_dir", "canonical_order", "find_score_table", "merge",
           "read_meta", "run_jobs", "score", "score_episode", "score_many", "score_to_file", "table_meta",
           "table_name"]
