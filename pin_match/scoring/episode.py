"""One episode into its chunks: the per-episode step that the local runner and the Dask runner share.

A run scores one or more jobs (a matcher and its product, ``product.Job``) in one pass: each
frame is decoded once, in a thread pool ahead of the matchers, made RGB once, and handed to
every job as one batch (``contract.frames.Frames``), which computes a matcher that several ask
for (``verify``'s locate map is ``effnet``'s scores) once and lends each its own copy. Each job's
rows land in its own chunk file; an episode whose chunks all exist is not scored again, and one
that lacks some is scored for those jobs only.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pin_match.contract.frames import Frames
from pin_match.contract.matcher import Matcher, MatcherError
from pin_match.data.frameset import FrameSet
from pin_match.scoring.product import Product
from pin_match.scoring.schema import chunk_rows, write_chunk


@dataclass(frozen=True)
class Output:
    """Where a job's chunks go and what they hold."""

    product: Product
    chunks: Path

    def done(self, episode_id: str, say_why: bool = True) -> int | None:
        """The rows of the episode's sound chunk, or None when it must be scored (``schema.chunk_rows``)."""
        return chunk_rows(self.chunks, episode_id, self.product.schema(), say_why=say_why)


class PreparedMatchers:
    """A run's matchers, the target each is prepared for, and the threads that decode frames ahead of them.

    A runner keeps one across episodes (the local runner one, a Dask worker one per thread), so
    consecutive episodes of one target, common in PIN, prepare it once. One episode at a time
    uses it, because ``prepare`` changes a matcher. ``workers`` > 1 also matches a batch's
    frames in parallel, for matchers that allow it.
    """

    def __init__(self, matchers: Sequence[Matcher], workers: int = 1) -> None:
        self.matchers = list(matchers)
        for matcher in self.matchers:  # a composite's part configured as another matcher of the run is prepared once
            matcher.share_parts(self.matchers)
        self.workers = workers
        self.targets: list[str | None] = [None] * len(self.matchers)
        self.pool = ThreadPoolExecutor(max_workers=max(2, workers))

    def hold(self, fs: FrameSet, target_id: str, which: Sequence[int]) -> None:
        """Prepare the matchers ``which`` for the target (each of them once, however many episodes of it follow)."""
        todo = [i for i in which if self.targets[i] != target_id]
        if not todo:
            return
        target = fs.target(target_id)
        for i in todo:
            self.targets[i] = None  # a failed prepare leaves nothing held
            self.matchers[i].prepare(target)
            self.targets[i] = target_id

    def forget(self) -> None:
        """After a failed episode: a matcher may be half-prepared, so the next episode prepares again."""
        self.targets = [None] * len(self.matchers)

    def __enter__(self) -> PreparedMatchers:
        return self

    def __exit__(self, *exc) -> None:
        self.pool.shutdown()


def score_into_chunks(fs: FrameSet, prepared: PreparedMatchers, outputs: Sequence[Output], episode_id: str, *,
                      batch_size: int, bar=None, say_why: bool = True) -> int:
    """Score the episode for every job without a sound chunk and write their chunks; returns its frames.

    ``bar`` counts frames once per episode, also when every chunk was found written.
    """
    pending = [i for i, out in enumerate(outputs) if out.done(episode_id, say_why) is None]
    n_frames = int((fs.frames.episode_id == episode_id).sum())
    if not pending:
        if bar is not None:
            bar.update(n_frames)
        return n_frames
    rows = score_episode(fs, prepared, [outputs[i].product for i in pending], episode_id, pending,
                         batch_size=batch_size, bar=bar)
    target_id = fs.episode(episode_id).target_object_id
    for i, part in zip(pending, rows):  # the matchers are still prepared for the episode's target
        product = outputs[i].product
        write_chunk(outputs[i].chunks, episode_id, part, product.schema(),
                    {target_id: product.notes(prepared.matchers[i])})
    return n_frames


def score_episode(fs: FrameSet, prepared: PreparedMatchers, products: Sequence[Product], episode_id: str,
                  which: Sequence[int], *, batch_size: int, bar=None) -> list[pd.DataFrame]:
    """The episode's rows for the matchers ``which`` (indices into ``prepared``), each by its product, in step
    order; ``bar`` counts frames."""
    ep = fs.episode(episode_id)
    frames = fs.frames[fs.frames.episode_id == episode_id].sort_values("step")
    prepared.hold(fs, ep.target_object_id, which)
    pool = prepared.pool
    ids = list(frames.frame_id)
    batches = [ids[i:i + batch_size] for i in range(0, len(ids), batch_size)]
    results: list[list[Any]] = [[] for _ in which]
    # decoding runs ahead of matching in the pool, so it overlaps inference
    decoded = [pool.submit(lambda b=b: [fs.image(f) for f in b]) for b in batches[:2]]
    for k in range(len(batches)):
        # one batch for every job: a part several ask for runs once on it
        batch = Frames(decoded[k].result(), pool=pool, workers=prepared.workers)
        if k + 2 < len(batches):
            decoded.append(pool.submit(lambda b=batches[k + 2]: [fs.image(f) for f in b]))
        for out, i, product in zip(results, which, products):
            try:
                out.extend(product.compute(prepared.matchers[i], batch))
            except MatcherError as exc:
                raise MatcherError(f"{exc} (episode {episode_id!r}, frames {batches[k][0]}..{batches[k][-1]})") \
                    from exc
        if bar is not None:
            bar.update(len(batch))
    steps = frames.step.to_numpy()
    return [product.rows(fs, ep, ids, steps, out) for out, product in zip(results, products)]
