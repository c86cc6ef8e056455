"""What the scoring engine computes per frame: a matcher's scores, or another per-frame product a fit needs.

A product says how a batch of frames becomes results (``compute``), how one episode's results
become rows (``rows``), the columns and types of its chunks and tables (``schema``), where they
live in the cache (``folder``, ``prefix``), the metadata a table carries (``meta``) and how the
chunks become the table (``assemble``: one parquet file unless the product's readers need more,
such as ``training.features``'s memory-mapped token arrays). Everything
else, per-episode chunks, resume after a kill, locks, Dask, the progress bar and the cache rule,
is the engine's and the same for every product: ``pin_match.fitting.verifier``'s candidate
signals are one, computed like any score table.

A ``Job`` is one matcher and one product; a run scores several jobs in one pass over the frames
(each frame decoded once, a matcher several ask for computed once on each batch: ``contract.frames``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd

from pin_match.contract.frames import Frames
from pin_match.contract.matcher import Matcher, MatcherError
from pin_match.contract.results import notes_problem
from pin_match.data.frameset import FrameSet
from pin_match.scoring.cache import Shard, assemble, table_meta
from pin_match.scoring.schema import arrow_schema, episode_rows


@dataclass(frozen=True)
class Product:
    """A matcher's scores: one row per frame in the score table's columns (``schema.COLUMNS``)."""

    prefix: ClassVar[str] = "scores"

    def folder(self, matcher: Matcher) -> str:
        """The cache folder's name for this matcher (``cache.cache_dir``'s middle part)."""
        return matcher.id

    def compute(self, matcher: Matcher, frames: Frames) -> list[Any]:
        """The matcher's results on one batch, its own copy of them (the batch computes them once for every job
        and part that asks)."""
        return frames.results(matcher)

    def rows(self, fs: FrameSet, episode: Any, frame_ids: list[str], steps: np.ndarray,
             results: list[Any]) -> pd.DataFrame:
        """One episode's rows (``episode`` a row of ``fs.episodes``), in step order."""
        return episode_rows(episode.episode_id, str(episode.split), frame_ids, steps, results)

    def schema(self) -> Any:
        return arrow_schema()

    def notes(self, matcher: Matcher) -> dict:
        """What the matcher, prepared for an episode's target, says of it (stored per target with the table)."""
        notes = matcher.target_notes()
        problem = notes_problem(notes)
        if problem:
            raise MatcherError(f"matcher {matcher.display_name}: {problem}")
        return notes

    def meta(self, matcher: Matcher, fs: FrameSet, split: str | None, shard: Shard | None) -> dict:
        return table_meta(matcher, fs, split, shard)

    def assemble(self, final: Path, chunk_files: list[Path], meta: dict) -> None:
        """The table at ``final`` from the episodes' chunks (sound, in canonical order), carrying ``meta``; written
        last and atomically, so that a table that exists is whole (``cache.assemble``)."""
        assemble(final, chunk_files, meta, self.schema())


SCORES = Product()


@dataclass(frozen=True)
class Job:
    """One matcher and what the engine computes with it (its scores unless told otherwise)."""

    matcher: Matcher
    product: Product = SCORES
