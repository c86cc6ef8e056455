"""The score table: the contract between scoring and everything after it.

One row per scored frame with the frame score, the per-crop scores and every candidate
point with its own score, so any threshold can be applied later without a model. The
parquet file's metadata names the matcher, its config hash and the frame-set fingerprint.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.contract.results import points_above
from pin_match.errors import PinMatchError
from pin_match.scoring.schema import COLUMNS, TARGETS, decode_meta, encode_meta


class ScoreTableError(PinMatchError, ValueError):
    pass


@dataclass
class ScoreTable:
    frames: pd.DataFrame
    meta: dict = field(default_factory=dict)

    @property
    def matcher(self) -> str:
        return self.meta.get("matcher", "?")

    @property
    def matcher_id(self) -> str:
        return self.meta.get("matcher_id", self.matcher)

    @property
    def target_notes(self) -> dict[str, dict]:
        """Per target id, what the matcher's ``prepare`` derived for it (``Matcher.target_notes``; often nothing)."""
        return self.meta.get(TARGETS, {})

    def points(self, frame_id: str, sigma: float) -> np.ndarray:
        """(K, 2) frame coordinates of the target under threshold sigma."""
        row = self.frames.loc[self.frames.frame_id == frame_id]
        if row.empty:
            raise ScoreTableError(f"frame id {frame_id!r} is not in the score table of {self.matcher_id}")
        return points_at(row.iloc[0], sigma)

    def split(self, split: str | None) -> ScoreTable:
        if split in (None, "all"):
            return self
        return ScoreTable(self.frames[self.frames.split == split].reset_index(drop=True), self.meta)

    def write(self, path: str | Path) -> None:
        import pyarrow as pa

        require_columns(self.frames, f"score table of {self.matcher_id}")
        table = pa.Table.from_pandas(self.frames[COLUMNS], preserve_index=False)
        atomic.write_parquet(path, table.replace_schema_metadata({**(table.schema.metadata or {}),
                                                                  **encode_meta(self.meta)}))

    @classmethod
    def read(cls, path: str | Path) -> ScoreTable:
        import pyarrow.parquet as pq

        path = Path(path)
        if path.is_dir():
            path = table_in(path)
        if not path.exists():
            raise ScoreTableError(f"no score table at {path}")
        try:
            table = pq.read_table(path)
        except Exception as exc:  # pyarrow raises several kinds on a damaged file
            raise ScoreTableError(f"cannot read score table {path}: {exc}") from exc
        meta = decode_meta(table.schema.metadata)
        if meta is None:
            raise ScoreTableError(f"{path} is not a pin_match score table (no metadata)")
        frames = table.to_pandas()
        require_columns(frames, str(path))
        require_finite(frames.frame_id, frames.score, str(path), ScoreTableError)
        return cls(frames, meta)


def table_in(directory: Path) -> Path:
    """The score table a scoring run left in its cache folder: the merged ``scores_all.parquet``, else the only one."""
    merged = directory / "scores_all.parquet"
    if merged.exists():
        return merged
    candidates = sorted(directory.glob("scores*.parquet"))
    if len(candidates) == 1:
        return candidates[0]
    if not candidates:
        raise ScoreTableError(f"no score table (scores*.parquet) in {directory}")
    raise ScoreTableError(f"{directory} holds {len(candidates)} score tables ({', '.join(c.name for c in candidates)})"
                          f" and no scores_all.parquet: name one of them")


def require_columns(frames: pd.DataFrame, where: str, columns: Sequence[str] = COLUMNS) -> None:
    """A table without the columns of today's schema (one written by hand, or by an older version) is refused,
    naming the columns it lacks, before any of them is read."""
    missing = [c for c in columns if c not in frames.columns]
    if missing:
        raise ScoreTableError(f"{where} lacks columns {missing}")


def require_finite(frame_ids: pd.Series, scores: pd.Series, where: str,
                   error: type[PinMatchError] = ScoreTableError) -> None:
    """A non-finite score would silently count as unmatched: the one rule, naming the first bad frame."""
    values = np.asarray(scores, np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        raise error(f"{where}: frame {np.asarray(frame_ids)[bad][0]!r} has a non-finite score {values[bad][0]}")


def points_at(row: pd.Series, sigma: float) -> np.ndarray:
    """A stored row's target coordinates under sigma, by the same rule as ``MatchResult.points_at``."""
    points = np.stack([np.asarray(row["points_x"], np.float32), np.asarray(row["points_y"], np.float32)], axis=1)
    return points_above(float(row["score"]), points, np.asarray(row["point_scores"], np.float32), sigma)
