"""Score a frame-set with a matcher once; everything after reads the resulting table.

The cache lives at ``<out>/<matcher>@<config hash>/<frame-set fingerprint>/``: a changed
config or frame-set never reads a stale cache. Work is done per episode (the target is
prepared once, its frames batched) and each episode's rows land in their own chunk file,
written atomically, so a killed run resumes where it stopped, two processes can share a
cache, and the final table is the concatenation of the chunks in episode order: the
same bytes whether the run was interrupted or not.

Several matchers (or other per-frame products, ``product``) are scored in one pass
(``run_jobs``): each frame decoded once, a shared part run once, each job into its own table.

The episodes run either here (threads decode ahead of the matcher) or, given a Dask
``client``, a few per task on a cluster (``pin_match.scoring.cluster``); both write the same
chunk files and end in the same ``assemble``, so either path resumes the other's run.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from pin_match import atomic, outputs
from pin_match.contract.matcher import Matcher
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.scoring.cache import Shard, cache_dir, read_meta, table_name
from pin_match.scoring.episode import Output
from pin_match.scoring.local import score_here
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.product import Job
from pin_match.scoring.schema import chunk_path, produced_by
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
    the episodes are scored on its cluster, into the same cache and the same table: the same bytes for
    matchers whose arithmetic does not depend on the thread count (``color`` and ``sift`` are tested
    so); a network's float sums may differ in the last bits with a worker's threads (the test allows
    ``rtol=1e-4``, ``atol=1e-5`` on ``verify``'s candidate signals).
    """
    if isinstance(matcher, str):
        matcher = create_matcher(matcher, **(overrides or {}))
    return run_jobs(frameset, [Job(matcher)], split=split, out=out, shard=shard, run=run)[0]


def score_many(frameset: FrameSet | str | Path, matchers: Mapping[str, dict] | Sequence[Matcher | str], *,
               split: str | None = None, out: str | Path = outputs.SCORES,
               run: RunOptions = DEFAULT_RUN) -> list[ScoreTable]:
    """Several matchers' tables from one pass over the frames (``run_jobs``): the tables each alone would give.

    ``matchers``: matchers or names, or a mapping of name to config overrides.
    """
    built = [create_matcher(name, **(cfg or {})) for name, cfg in matchers.items()] if isinstance(matchers, Mapping) \
        else [create_matcher(m) if isinstance(m, str) else m for m in matchers]
    return [ScoreTable.read(p) for p in run_jobs(frameset, [Job(m) for m in built], split=split, out=out, run=run)]


def run_jobs(frameset: FrameSet | str | Path, jobs: Sequence[Job], *, split: str | None = None,
             out: str | Path = outputs.SCORES, shard: Shard | str | None = None,
             run: RunOptions = DEFAULT_RUN) -> list[Path]:
    """Every job's table of ``split`` (found in the cache, or computed in one pass over the frames); their paths.

    The jobs without a current table are run together: each frame is decoded once and handed to
    each of them in one batch, which computes a matcher several ask for once (``contract.frames``),
    so ``verify`` and ``effnet`` together cost little more than ``verify``. Each job's table lives at
    ``cache_dir(out, product.folder(matcher), fingerprint)`` and is the same bytes as the job
    run alone. Two jobs of one matcher and product are one job.
    """
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    if isinstance(shard, str):
        shard = Shard.parse(shard)
    if split in (None, "all"):  # a view of one split is that split: its table must not pass for the whole set's
        split = fs.split_name
    part = fs.split(split)
    episode_ids = list(part.episodes.episode_id)
    if shard is not None:
        episode_ids = shard.select(episode_ids)
    finals, todo = [], {}
    for job in jobs:
        root = cache_dir(out, job.product.folder(job.matcher), fs.fingerprint)
        final = root / table_name(split, shard, job.product.prefix)
        meta = job.product.meta(job.matcher, fs, split, shard)
        finals.append(final)
        if not (final.exists() and produced_by(read_meta(final), meta)) and final not in todo:
            todo[final] = (job, Output(job.product, atomic.ensure_dir(root / "chunks")), meta)
    if todo:
        _run(part, list(todo.values()), episode_ids, run)
        for final, (job, output, meta) in todo.items():
            job.product.assemble(final, [chunk_path(output.chunks, e) for e in sorted(episode_ids)], meta)
    return finals


def _run(part: FrameSet, todo: list[tuple[Job, Output, dict]], episode_ids: list[str], run: RunOptions) -> None:
    matchers = [job.matcher for job, _, _ in todo]
    outputs = [output for _, output, _ in todo]
    with _progress(part, episode_ids, run.progress, matchers) as bar:
        if run.client is not None:
            from pin_match.scoring.cluster import score_episodes

            score_episodes(run.client, part, matchers, outputs, episode_ids, run.batch_size, bar)
        else:
            score_here(part, matchers, outputs, episode_ids, run.batch_size,
                       run.workers or min(2, os.cpu_count() or 1), bar)


class _progress:
    """A tqdm bar in frames with the rate in frames per second (silent when disabled)."""

    def __init__(self, fs: FrameSet, episode_ids: list[str], enabled: bool, matchers: list[Matcher]) -> None:
        from tqdm import tqdm

        total = int(fs.frames.episode_id.isin(episode_ids).sum())
        self.bar = tqdm(total=total, unit="frame", desc="+".join(m.display_name for m in matchers),
                        disable=not enabled, dynamic_ncols=True, smoothing=0.1)

    def __enter__(self):
        return self.bar

    def __exit__(self, *exc) -> None:
        self.bar.close()
