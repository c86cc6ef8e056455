"""What a score table and its chunk files hold, how the table's metadata is stored, and when a chunk counts.

One module, so that the runners that write chunks, the cache that assembles them and
``ScoreTable`` that reads the result cannot disagree. A chunk is one episode's rows in exactly
the table's columns and types (the chunks of another per-frame product, ``product``, in its own
schema, by the same rules). A chunk that cannot be read, or whose columns or types differ
(a disk that filled up, a copy cut short, a file from another version), is damaged: its
episode is scored again and the chunk replaced, so a damaged cache costs time, never a
traceback and never a wrong table.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.contract.matcher import MatchResult

_TEXT, _INT, _FLOAT, _FLOATS = "text", "int64", "float64", "float32 list"
_TYPES = {"frame_id": _TEXT, "episode_id": _TEXT, "step": _INT, "split": _TEXT, "score": _FLOAT,
          "crop_scores": _FLOATS, "points_x": _FLOATS, "points_y": _FLOATS, "point_scores": _FLOATS,
          "view": _INT}  # the reference view the frame's best box matched (``MatchResult.best_view``; -1: none named)
COLUMNS = list(_TYPES)
META_KEY = b"pin_match"
NOTES_KEY = b"pin_match_target_notes"  # a chunk's: {target id: what prepare derived} (``Matcher.target_notes``)
TARGETS = "targets"  # the table's metadata key gathering its chunks' notes


def arrow_schema() -> Any:
    """The score table's columns' Arrow types.

    Text is ``large_string`` whichever pandas version built the rows, so every chunk of a table
    has one type; lists name their values ``element`` as parquet stores them, so the schema
    written is the one read back.
    """
    import pyarrow as pa

    arrow = {_TEXT: pa.large_string(), _INT: pa.int64(), _FLOAT: pa.float64(),
             _FLOATS: pa.list_(pa.field("element", pa.float32()))}
    return pa.schema([(name, arrow[kind]) for name, kind in _TYPES.items()])


def episode_rows(episode_id: str, split: str, frame_ids: list[str], steps: np.ndarray,
                 results: list[MatchResult]) -> pd.DataFrame:
    """One episode's rows in the table's columns and types, in step order.

    A matcher that scores the frame as a whole has no crop scores: its frame score stands as
    the one crop score, so every row has at least one. Of the boxes only the best one's view is
    kept, all a report says of them.
    """
    return pd.DataFrame(dict(
        frame_id=frame_ids, episode_id=episode_id, step=np.asarray(steps, np.int64), split=str(split),
        score=np.array([r.score for r in results], np.float64),
        crop_scores=[(r.crop_scores if r.crop_scores is not None else np.array([r.score])).astype(np.float32)
                     for r in results],
        points_x=[r.points[:, 0].astype(np.float32) for r in results],
        points_y=[r.points[:, 1].astype(np.float32) for r in results],
        point_scores=[r.scores_of_points().astype(np.float32) for r in results],
        view=np.array([r.best_view() for r in results], np.int64),
    ))


def encode_meta(meta: dict) -> dict[bytes, bytes]:
    """The table's metadata as parquet schema metadata: JSON with sorted keys, so equal metadata is equal bytes."""
    return {META_KEY: json.dumps(meta, sort_keys=True, default=str).encode()}


def decode_meta(schema_metadata: dict | None) -> dict | None:
    """The metadata ``encode_meta`` stored, or None for a parquet file that is no pin_match table."""
    raw = (schema_metadata or {}).get(META_KEY)
    return json.loads(raw) if raw else None


def produced_by(stored: dict | None, expected: dict) -> bool:
    """Whether a table's stored metadata is ``expected``'s: the run's own, apart from the targets' notes it gathered."""
    return stored is not None and {k: v for k, v in stored.items() if k != TARGETS} == expected


def as_stored(meta: dict) -> dict:
    """``meta`` as it reads back from a table (tuples become lists, paths text), so a cached table compares equal."""
    return json.loads(encode_meta(meta)[META_KEY])


def mismatch(schema: Any, expected: Any) -> str | None:
    """Why an Arrow schema is not ``expected`` (ignoring metadata), or None when it is."""
    if schema.names != expected.names:
        return f"columns {schema.names}, expected {expected.names}"
    for field in expected:
        got = schema.field(field.name).type
        if got != field.type:
            return f"column {field.name} is {got}, expected {field.type}"
    return None


def chunk_path(chunks: Path, episode_id: str) -> Path:
    return Path(chunks) / f"{episode_id}.parquet"


def write_chunk(chunks: Path, episode_id: str, rows: pd.DataFrame, schema: Any, notes: dict) -> None:
    """Write the episode's rows atomically, in the types of ``schema`` (replacing a damaged chunk), with ``notes``
    ({target id: notes}; nothing when the matcher has none) in its metadata."""
    import pyarrow as pa

    if any(notes.values()):
        schema = schema.with_metadata({NOTES_KEY: json.dumps(notes, sort_keys=True).encode()})
    atomic.write_parquet(chunk_path(chunks, episode_id),
                         pa.Table.from_pandas(rows[schema.names], schema=schema, preserve_index=False))


def chunk_notes(schema_metadata: dict | None) -> dict:
    """The target notes a chunk carries ({} for none)."""
    raw = (schema_metadata or {}).get(NOTES_KEY)
    return json.loads(raw) if raw else {}


def chunk_rows(chunks: Path, episode_id: str, schema: Any, *, say_why: bool = True) -> int | None:
    """The number of rows of the episode's chunk, or None when the episode must be scored.

    That is when there is no chunk, or a damaged one; with ``say_why`` a damaged chunk is named
    on stderr in one line. The whole chunk is read, not only its footer, because the final
    table is assembled from the chunks' rows and a damaged page found there would end the run.
    """
    import pyarrow.parquet as pq

    path = chunk_path(chunks, episode_id)
    if not path.exists():
        return None
    try:
        table = pq.read_table(path)
    except Exception as exc:  # pyarrow raises several kinds (ArrowInvalid, OSError, ...) on a damaged file
        problem = " ".join(str(exc).split()) or type(exc).__name__
    else:
        problem = mismatch(table.schema, schema)
        if problem is None:
            return table.num_rows
    if say_why:
        print(f"pin-match: damaged score chunk {path} ({problem}): scoring episode {episode_id!r} again",
              file=sys.stderr)
    return None
