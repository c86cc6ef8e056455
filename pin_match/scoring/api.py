"""Score a frame-set with a matcher once; everything after reads the resulting table.

The cache lives at ``<out>/<matcher>@<config hash>/<frame-set fingerprint>/``: a changed
config or frame-set never reads a stale cache. Work is done per episode (the target is
prepared once, its frames batched) and each episode's rows land in their own chunk file,
written atomically, so a killed run resumes where it stopped, two processes can share a
cache, and the final table is the concatenation of the chunks in episode order: the
same bytes whether the run was interrupted or not.

The episodes run either here (threads decode ahead of the matcher) or, given a Dask
``client``, a few per task on a cluster (``pin_match.scoring.cluster``); both write the same
chunk files and end in the same ``assemble``, so either path resumes the other's run.
"""

from __future__ import annotations

import os
from pathlib import Path

from pin_match import atomic, outputs
from pin_match.contract.matcher import Matcher
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.scoring.cache import Shard, assemble, cache_dir, read_meta, table_meta, table_name
from pin_match.scoring.local import score_here
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.schema import chunk_path
from pin_match.scoring.table import ScoreTable


def score(frameset: FrameSet | str | Path, matcher: Matcher | str, *, overrides: dict | None = None,
          split: str | None = None, out: str | Path = outputs.SCORES, shard: Shard | str | None = None,
          run: RunOptions = DEFAULT_RUN) -> ScoreTable:
    """Score every frame of ``split`` (cached); returns the score table and writes it under ``out``.

    The arguments are those of ``score_to_file``.
    """
    return ScoreTable.read(score_to_file(frameset, matcher, overrides=overrides, split=split, out=out, shard=shard,
                                         run=run))


def score_to_file(frameset: FrameSet | str | Path, matcher: Matcher | str, *, overrides: dict | None = None,
                  split: str | None = None, out: str | Path = outputs.SCORES, shard: Shard | str | None = None,
                  run: RunOptions = DEFAULT_RUN) -> Path:
    """Score (or find in the cache) and return the table's path; memory stays flat in the number of frames.

    ``overrides`` configure a matcher given by name (weights included: ``registry.with_weights``).
    ``shard`` ("K/N") scores one part of the episodes. With ``run.client`` (a ``distributed.Client``)
    the episodes are scored on its cluster, into the same cache and the same table bytes.
    """
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    if isinstance(matcher, str):
        matcher = create_matcher(matcher, **(overrides or {}))
    if isinstance(shard, str):
        shard = Shard.parse(shard)
    part = fs.split(split)
    episode_ids = list(part.episodes.episode_id)
    if shard is not None:
        episode_ids = shard.select(episode_ids)
    root = cache_dir(out, matcher.id, fs.fingerprint)
    final = root / table_name(split, shard)
    meta = table_meta(matcher, fs, split, shard)
    if final.exists() and read_meta(final) == meta:
        return final
    chunks = atomic.ensure_dir(root / "chunks")
    with _progress(part, episode_ids, run.progress, matcher) as bar:
        if run.client is not None:
            from pin_match.scoring.cluster import score_episodes

            score_episodes(run.client, part, matcher, episode_ids, chunks, run.batch_size, bar)
        else:
            score_here(part, matcher, episode_ids, chunks, run.batch_size,
                       run.workers or min(2, os.cpu_count() or 1), bar)
    assemble(final, [chunk_path(chunks, e) for e in sorted(episode_ids)], meta)
    return final


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
