"""Score a frame-set with a matcher once; everything after reads the resulting table.

The cache lives at ``<out>/<matcher>@<config hash>/<frame-set fingerprint>/``: a changed
config or frame-set never reads a stale cache. Work is done per episode (the target is
prepared once, its frames batched) and each episode's rows land in their own chunk file,
written atomically, so a killed run resumes where it stopped, two processes can share a
cache, and the final table is the concatenation of the chunks in episode order: the
same bytes whether the run was interrupted or not.

The episodes run either here (threads decode ahead of the matcher) or, given a Dask
``client``, as one task each on a cluster (``pin_match.distributed``); both write the same
chunk files and end in the same ``_assemble``, so either path resumes the other's run.
"""

from __future__ import annotations

import errno
import json
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

import pin_match
from pin_match import atomic
from pin_match.frameset import FrameSet
from pin_match.matcher import Matcher, MatcherError, MatchResult
from pin_match.registry import create_matcher
from pin_match.scoretable import COLUMNS, META_KEY, ScoreTable, ScoreTableError

DEFAULT_OUT = Path("pin_match_runs") / "scores"
LOCK_STALE_S = 600.0
LOCK_EMPTY_S = 5.0  # a lock still without a pid after this long was left by a process killed while taking it


@dataclass(frozen=True)
class Shard:
    index: int
    count: int

    @classmethod
    def parse(cls, text: str) -> Shard:
        try:
            i, n = (int(x) for x in text.split("/"))
        except ValueError:
            raise ValueError(f"--shard {text!r}: expected i/n, e.g. 0/4") from None
        if not (n >= 1 and 0 <= i < n):
            raise ValueError(f"--shard {text!r}: need 0 <= i < n")
        return cls(i, n)

    def select(self, episode_ids: list[str]) -> list[str]:
        """A deterministic part: every n-th episode in frame-set order."""
        return episode_ids[self.index::self.count]

    def __str__(self) -> str:
        return f"{self.index}of{self.count}"


def cache_dir(out: str | Path, matcher: Matcher, fs: FrameSet) -> Path:
    return Path(out) / matcher.id / fs.fingerprint


def table_name(split: str | None, shard: Shard | None) -> str:
    name = f"scores_{split or 'all'}"
    return f"{name}_shard{shard}.parquet" if shard else f"{name}.parquet"


def score(frameset: FrameSet | str | Path, matcher: Matcher | str, **kwargs) -> ScoreTable:
    """Score every frame of ``split`` (cached); returns the score table and writes it under ``out``.

    Keyword arguments are those of ``score_to_file``.
    """
    return ScoreTable.read(score_to_file(frameset, matcher, **kwargs))


def score_to_file(frameset: FrameSet | str | Path, matcher: Matcher | str, *, overrides: dict | None = None,
                  weights: str | None = None, split: str | None = None, out: str | Path = DEFAULT_OUT,
                  batch_size: int = 8, shard: Shard | str | None = None, workers: int | None = None,
                  progress: bool = True, client=None) -> Path:
    """Score (or find in the cache) and return the table's path; memory stays flat in the number of frames.

    With a ``distributed.Client`` the episodes are scored on its cluster (``workers`` is then unused),
    into the same cache and the same table bytes.
    """
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    if isinstance(matcher, str):
        overrides = dict(overrides or {})
        if weights is not None:
            overrides["weights"] = weights
        matcher = create_matcher(matcher, **overrides)
    if isinstance(shard, str):
        shard = Shard.parse(shard)
    part = fs.split(split)
    episode_ids = list(part.episodes.episode_id)
    if shard is not None:
        episode_ids = shard.select(episode_ids)
    root = cache_dir(out, matcher, fs)
    final = root / table_name(split, shard)
    meta = table_meta(matcher, fs, split, shard)
    if final.exists() and read_meta(final) == meta:
        return final
    chunks = atomic.ensure_dir(root / "chunks")
    with _progress(part, episode_ids, progress, matcher) as bar:
        if client is not None:
            from pin_match.distributed import score_episodes

            score_episodes(client, part, matcher, episode_ids, chunks, batch_size, bar)
        else:
            _score_here(part, matcher, episode_ids, chunks, batch_size, workers or min(2, os.cpu_count() or 1), bar)
    _assemble(final, [chunks / f"{e}.parquet" for e in sorted(episode_ids)], meta)
    return final


def _score_here(part: FrameSet, matcher: Matcher, episode_ids: list[str], chunks: Path, batch_size: int,
                workers: int, bar) -> None:
    """Score the episodes without a chunk in this process, taking turns with other processes through lock files."""
    held: dict[str, str] = {}
    with ThreadPoolExecutor(max_workers=max(2, workers)) as pool:
        pending = list(episode_ids)
        while pending:
            deferred = []
            for episode_id in pending:
                if (chunks / f"{episode_id}.parquet").exists():
                    bar.update(int((part.frames.episode_id == episode_id).sum()))
                    continue
                lock = _try_lock(chunks / f"{episode_id}.lock")
                if lock is None:  # another process is scoring it right now
                    deferred.append(episode_id)
                    continue
                try:
                    rows = _score_episode(part, matcher, episode_id, batch_size, pool, workers, bar, held)
                    atomic.write_parquet(chunks / f"{episode_id}.parquet", rows)
                finally:
                    lock.unlink(missing_ok=True)
            if deferred:
                time.sleep(0.2)
            pending = deferred


def _assemble(final: Path, chunk_files: list[Path], meta: dict) -> None:
    """Stream the chunks, in canonical (episode, step) order, into one parquet file carrying the metadata."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = pa.Schema.from_pandas(_empty_rows(), preserve_index=False)
    if chunk_files:
        schema = pq.read_schema(chunk_files[0]).remove_metadata()
    schema = schema.with_metadata({META_KEY: json.dumps(meta, sort_keys=True, default=str).encode()})
    with atomic.atomic_path(final) as tmp, pq.ParquetWriter(tmp, schema) as writer:
        for path in chunk_files:
            writer.write_table(pq.read_table(path).select(COLUMNS).replace_schema_metadata(schema.metadata))


def read_meta(path: Path) -> dict | None:
    """A score table's metadata without reading its rows."""
    import pyarrow.parquet as pq

    try:
        raw = (pq.read_schema(path).metadata or {}).get(META_KEY)
    except Exception:  # a damaged file is simply not a cache hit
        return None
    return json.loads(raw) if raw else None


def table_meta(matcher: Matcher, fs: FrameSet, split: str | None, shard: Shard | None) -> dict:
    """The metadata a table carries, as it reads back from JSON (so a cached table compares equal)."""
    meta = dict(matcher=matcher.display_name, matcher_id=matcher.id, config_hash=matcher.config_hash,
                config=matcher.cfg.hashed_dict(), frameset_fingerprint=fs.fingerprint,
                frameset_name=fs.manifest.get("name", ""), split=split or "all",
                shard=str(shard) if shard else None, default_sigma=matcher.default_sigma,
                modality=matcher.modality.value, pin_match_version=pin_match.__version__)
    return json.loads(json.dumps(meta, default=str))


def _score_episode(fs: FrameSet, matcher: Matcher, episode_id: str, batch_size: int, pool: ThreadPoolExecutor,
                   workers: int, bar=None, held: dict[str, str] | None = None) -> pd.DataFrame:
    """One episode's rows. ``held`` remembers the target the matcher is prepared for, so that
    consecutive episodes of one target (common in PIN) prepare it once; ``bar`` counts frames."""
    ep = fs.episode(episode_id)
    frames = fs.frames[fs.frames.episode_id == episode_id].sort_values("step")
    held = {} if held is None else held
    if held.get("target") != ep.target_object_id:
        held.pop("target", None)  # a failed prepare leaves nothing held
        matcher.prepare(fs.target(ep.target_object_id))
        held["target"] = ep.target_object_id
    ids = list(frames.frame_id)
    batches = [ids[i:i + batch_size] for i in range(0, len(ids), batch_size)]
    results: list[MatchResult] = []
    # decoding runs ahead of matching in the pool, so it overlaps inference
    decoded = [pool.submit(lambda b=b: [fs.image(f) for f in b]) for b in batches[:2]]
    parallel = matcher.parallel_frames and workers > 1
    for k in range(len(batches)):
        images = decoded[k].result()
        if k + 2 < len(batches):
            decoded.append(pool.submit(lambda b=batches[k + 2]: [fs.image(f) for f in b]))
        try:
            if parallel:
                parts = np.array_split(np.arange(len(images)), min(workers, len(images)))
                futures = [pool.submit(matcher.match_batch, [images[i] for i in p]) for p in parts if len(p)]
                out = [r for f in futures for r in f.result()]
            else:
                out = matcher.match_batch(images)
        except MatcherError as exc:
            raise MatcherError(f"{exc} (episode {episode_id!r}, frames {batches[k][0]}..{batches[k][-1]})") from exc
        results.extend(out)
        if bar is not None:
            bar.update(len(images))
    return pd.DataFrame(dict(
        frame_id=ids, episode_id=episode_id, step=frames.step.to_numpy(np.int64), split=str(ep.split),
        score=np.array([r.score for r in results], np.float64),
        crop_scores=[(r.crop_scores if r.crop_scores is not None else np.array([r.score])).astype(np.float32)
                     for r in results],
        points_x=[r.points[:, 0].astype(np.float32) for r in results],
        points_y=[r.points[:, 1].astype(np.float32) for r in results],
        point_scores=[r.scores_of_points().astype(np.float32) for r in results],
    ))


def _empty_rows() -> pd.DataFrame:
    """The table's columns with their types, for a part with no episodes."""
    lists = {c: pd.Series([], dtype=object) for c in ("crop_scores", "points_x", "points_y", "point_scores")}
    return pd.DataFrame({"frame_id": pd.Series([], dtype=object), "episode_id": pd.Series([], dtype=object),
                         "step": pd.Series([], dtype=np.int64), "split": pd.Series([], dtype=object),
                         "score": pd.Series([], dtype=np.float64), **lists})[COLUMNS]


def _try_lock(path: Path) -> Path | None:
    """An exclusive per-episode lock file; a lock older than LOCK_STALE_S or of a dead pid is taken over."""
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            if _lock_is_stale(path):
                path.unlink(missing_ok=True)
                continue
            return None
        except OSError as exc:
            if exc.errno in (errno.EROFS, errno.EACCES, errno.ENOSPC):
                raise atomic.OutputError(f"cannot write into {path.parent}: {exc.strerror}") from exc
            raise
        with os.fdopen(fd, "w") as fh:
            fh.write(str(os.getpid()))
        return path
    return None


def _lock_is_stale(path: Path) -> bool:
    try:
        text = path.read_text()
        age = time.time() - path.stat().st_mtime
        pid = int(text or "0")
    except (OSError, ValueError):
        return True
    if age > LOCK_STALE_S:
        return True
    if pid <= 0:  # its writer is between creating it and writing the pid, or was killed there
        return age > LOCK_EMPTY_S
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


class _progress:
    """A tqdm bar in frames with the rate in frames per second (silent when disabled)."""

    def __init__(self, fs: FrameSet, episode_ids: list[str], enabled: bool, matcher: Matcher) -> None:
        from tqdm import tqdm

        total = int(fs.frames.episode_id.isin(episode_ids).sum())
        self.bar = tqdm(total=total, unit="frame", desc=matcher.display_name, disable=not enabled,
                        dynamic_ncols=True, smoothing=0.1)

    def __enter__(self):
        return self.bar

    def __exit__(self, *exc) -> None:
        self.bar.close()


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
    table = ScoreTable(frames[COLUMNS], meta)
    table.write(out)
    return table


def canonical_order(frames: pd.DataFrame) -> pd.DataFrame:
    """Rows sorted by (episode, step): the one order every path to a table ends in."""
    return frames.sort_values(["episode_id", "step"], kind="stable").reset_index(drop=True)
