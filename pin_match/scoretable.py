"""The score table: the contract between scoring and everything after it.

One row per scored frame with the frame score, the per-crop scores and every candidate
point with its own score, so any threshold can be applied later without a model. The
parquet file's metadata names the matcher, its config hash and the frame-set fingerprint.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.errors import PinMatchError

COLUMNS = ["frame_id", "episode_id", "step", "split", "score", "crop_scores", "points_x", "points_y",
           "point_scores"]
META_KEY = b"pin_match"


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

        table = pa.Table.from_pandas(self.frames[COLUMNS], preserve_index=False)
        meta = dict(table.schema.metadata or {})
        meta[META_KEY] = json.dumps(self.meta, sort_keys=True, default=str).encode()
        atomic.write_parquet(path, table.replace_schema_metadata(meta))

    @classmethod
    def read(cls, path: str | Path) -> ScoreTable:
        import pyarrow.parquet as pq

        path = Path(path)
        if path.is_dir():
            path = path / "scores.parquet"
        if not path.exists():
            raise ScoreTableError(f"no score table at {path}")
        try:
            table = pq.read_table(path)
        except Exception as exc:  # pyarrow raises several kinds on a damaged file
            raise ScoreTableError(f"cannot read score table {path}: {exc}") from exc
        raw = (table.schema.metadata or {}).get(META_KEY)
        if raw is None:
            raise ScoreTableError(f"{path} is not a pin_match score table (no metadata)")
        frames = table.to_pandas()
        missing = [c for c in COLUMNS if c not in frames.columns]
        if missing:
            raise ScoreTableError(f"{path} lacks columns {missing}")
        if not np.isfinite(frames.score.to_numpy(float)).all():
            bad = frames.frame_id[~np.isfinite(frames.score.to_numpy(float))].iloc[0]
            raise ScoreTableError(f"{path}: frame {bad!r} has a non-finite score")
        return cls(frames, json.loads(raw))


def points_at(row: pd.Series, sigma: float) -> np.ndarray:
    if row["score"] < sigma:
        return np.zeros((0, 2), np.float32)
    keep = np.asarray(row["point_scores"], np.float32) >= sigma
    return np.stack([np.asarray(row["points_x"], np.float32)[keep], np.asarray(row["points_y"], np.float32)[keep]],
                    axis=1)
