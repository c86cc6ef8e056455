"""The score cache: one folder rule, the table's name and metadata, assembling, finding and merging tables.

A table lives at ``<root>/<matcher id>/<frame-set fingerprint>/scores_<split>[_shard<i>of<n>].parquet``.
The matcher id is the registry name plus a hash of the resolved config and the weights'
identity (never a module path), so a changed config or frame-set never reads a stale
table, and a table stays found when code moves.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

import pin_match
from pin_match import atomic
from pin_match.contract.matcher import Matcher
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.scoring.schema import COLUMNS, TARGETS, as_stored, chunk_notes, decode_meta, encode_meta
from pin_match.scoring.table import ScoreTable, ScoreTableError, table_in


class ShardError(PinMatchError, ValueError):
    """A ``--shard`` that is not ``i/n`` with ``0 <= i < n``."""


@dataclass(frozen=True)
class Shard:
    index: int
    count: int

    @classmethod
    def parse(cls, text: str) -> Shard:
        try:
            i, n = (int(x) for x in text.split("/"))
        except ValueError:
            raise ShardError(f"--shard {text!r}: expected i/n, e.g. 0/4") from None
        if not (n >= 1 and 0 <= i < n):
            raise ShardError(f"--shard {text!r}: need 0 <= i < n")
        return cls(i, n)

    def select(self, episode_ids: list[str]) -> list[str]:
        """A deterministic part: every n-th episode in frame-set order."""
        return episode_ids[self.index::self.count]

    def __str__(self) -> str:
        return f"{self.index}of{self.count}"


def cache_dir(root: str | Path, matcher_id: str, fingerprint: str) -> Path:
    """The one folder rule for everything computed per (matcher config, frame-set): scores, features, reports."""
    return Path(root) / matcher_id / fingerprint


def table_name(split: str | None, shard: Shard | None, prefix: str = "scores") -> str:
    """A table's file name: ``prefix`` is the product's (``scores``, or another per-frame product's)."""
    name = f"{prefix}_{split or 'all'}"
    return f"{name}_shard{shard}.parquet" if shard else f"{name}.parquet"


def read_meta(path: Path) -> dict | None:
    """A score table's metadata without reading its rows; None when the file or its metadata is missing or damaged.

    A missing or damaged file is simply not a cache hit. A file the system refuses to read (permissions,
    a disk error) is a ScoreTableError naming it: taken for a miss, it would be scored again over it.
    """
    import pyarrow.parquet as pq

    try:
        return decode_meta(pq.read_schema(path).metadata)
    except (FileNotFoundError, ValueError):  # ValueError: pyarrow's ArrowInvalid (not parquet) or damaged JSON
        return None
    except OSError as exc:
        if exc.errno is None:  # pyarrow's own "cannot parse the footer": a damaged file, no system error
            return None
        raise ScoreTableError(f"cannot read the score table {path} ({type(exc).__name__}: {exc})") from exc


def table_meta(matcher: Matcher, fs: FrameSet, split: str | None, shard: Shard | None) -> dict:
    """The metadata a table carries, as it reads back (so a cached table compares equal). It names the table's
    columns, so a table of an older version's columns is no cache hit (its chunks, in those columns too, count as
    damaged and are scored again: ``schema.chunk_rows``)."""
    meta = dict(columns=COLUMNS, matcher=matcher.display_name, matcher_id=matcher.id, config_hash=matcher.config_hash,
                config=matcher.cfg.hashed_dict(), frameset_fingerprint=fs.fingerprint,
                frameset_name=fs.manifest.get("name", ""), split=split or "all",
                shard=str(shard) if shard else None, default_sigma=matcher.default_sigma,
                score_scale=matcher.score_scale, modality=matcher.modality.value,
                pin_match_version=pin_match.__version__)
    return as_stored(meta)


def assemble(final: Path, chunk_files: list[Path], meta: dict, schema: Any) -> None:
    """Stream the chunks, in canonical (episode, step) order, into one parquet file carrying the metadata.

    The chunks have passed ``schema.chunk_rows`` (or were just written), so they hold ``schema``'s
    types (the product's: ``product.Product.schema``). The notes of their targets
    (``Matcher.target_notes``) are gathered under the metadata's ``targets``.
    """
    import pyarrow.parquet as pq

    notes = {}
    for path in chunk_files:
        notes.update(chunk_notes(pq.read_schema(path).metadata))
    schema = schema.with_metadata(encode_meta({**meta, TARGETS: notes} if notes else meta))
    with atomic.atomic_path(final) as tmp, pq.ParquetWriter(tmp, schema) as writer:
        for path in chunk_files:
            writer.write_table(pq.read_table(path).replace_schema_metadata(schema.metadata))


def canonical_order(frames: pd.DataFrame) -> pd.DataFrame:
    """Rows sorted by (episode, step): the one order every path to a table ends in."""
    return frames.sort_values(["episode_id", "step"], kind="stable").reset_index(drop=True)


def find_score_table(cache: str | Path, fs: FrameSet, matcher: str, overrides: dict | None = None) -> Path:
    """The table ``pin-match score FS --matcher NAME [--cfg ...]`` wrote into ``cache``."""
    m = create_matcher(matcher, **(overrides or {}))
    cache = Path(cache)
    folder = cache_dir(cache, m.id, fs.fingerprint)
    if folder.is_dir():
        return table_in(folder)
    others = sorted(p.parent.name for p in cache.glob(f"{m.display_name}@*/{fs.fingerprint}") if p.is_dir())
    if others:
        raise ScoreTableError(f"{cache} holds no table of {m.id} (this configuration) for frame-set {fs.root}, only "
                              f"of {', '.join(others)}: pass the same --cfg / --weights as to `pin-match score`, "
                              "or the table's path")
    raise ScoreTableError(f"{cache} holds no score table of {matcher} for frame-set {fs.root} ({fs.fingerprint}): "
                          f"run `pin-match score {fs.root} --matcher {matcher}` first (or pass --cache)")


def merge(parts: list[str | Path], out: str | Path) -> ScoreTable:
    """Join shard tables of one matcher and frame-set into one table, rows sorted by (episode id, step).

    That is ``canonical_order``, the order every scoring path writes (episode ids sorted as text,
    not the frame-set's episode order), so a merged table equals an unsharded run's.
    """
    tables = [ScoreTable.read(p) for p in parts]
    if not tables:
        raise ScoreTableError("merge needs at least one score table")
    first = tables[0].meta
    for p, t in zip(parts, tables):
        for key in ("matcher_id", "frameset_fingerprint", "split"):
            if t.meta.get(key) != first.get(key):
                raise ScoreTableError(f"{p}: {key} {t.meta.get(key)!r} differs from {first.get(key)!r} of {parts[0]}")
    frames = pd.concat([t.frames for t in tables], ignore_index=True)
    dup = frames.frame_id[frames.frame_id.duplicated()]
    if len(dup):
        raise ScoreTableError(f"frame {dup.iloc[0]!r} appears in more than one part")
    frames = canonical_order(frames)
    counts = {str(t.meta.get("shard")) for t in tables}
    meta = dict(first, shard=None, merged_from=sorted(counts))
    notes = {target: n for t in tables for target, n in t.target_notes.items()}
    if notes:
        meta[TARGETS] = notes
    table = ScoreTable(frames[COLUMNS], meta)
    table.write(out)
    return table
