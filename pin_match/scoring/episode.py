"""One episode into its chunk: the per-episode step that the local runner and the Dask runner share.

The target is prepared once per episode (or kept from the previous episode of the same
target), frames are decoded ahead of the matcher in a thread pool, and the rows come back
in step order as the episode's chunk.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match.contract.matcher import Matcher, MatcherError, MatchResult
from pin_match.data.frameset import FrameSet
from pin_match.scoring.schema import chunk_rows, episode_rows, write_chunk


class PreparedMatcher:
    """A matcher, the target it is prepared for, and the threads that decode frames ahead of it.

    A runner keeps one across episodes (the local runner one, a Dask worker one per thread), so
    consecutive episodes of one target, common in PIN, prepare it once. One episode at a time
    uses it, because ``prepare`` changes the matcher. ``workers`` > 1 also matches a batch's
    frames in parallel, for matchers that allow it.
    """

    def __init__(self, matcher: Matcher, workers: int = 1) -> None:
        self.matcher = matcher
        self.workers = workers
        self.target: str | None = None
        self.pool = ThreadPoolExecutor(max_workers=max(2, workers))

    def hold(self, fs: FrameSet, target_id: str) -> None:
        if self.target != target_id:
            self.target = None  # a failed prepare leaves nothing held
            self.matcher.prepare(fs.target(target_id))
            self.target = target_id

    def forget(self) -> None:
        """After a failed episode: the matcher may be half-prepared, so the next episode prepares again."""
        self.target = None

    def __enter__(self) -> PreparedMatcher:
        return self

    def __exit__(self, *exc) -> None:
        self.pool.shutdown()


def score_into_chunk(fs: FrameSet, prepared: PreparedMatcher, chunks: Path, episode_id: str, *, batch_size: int,
                     bar=None, say_why: bool = True) -> int:
    """Score the episode into its chunk unless a sound chunk exists (``schema.chunk_rows``); returns its rows.

    ``bar`` counts frames, also those of a chunk found written.
    """
    done = chunk_rows(chunks, episode_id, say_why=say_why)
    if done is not None:
        if bar is not None:
            bar.update(done)
        return done
    rows = score_episode(fs, prepared, episode_id, batch_size=batch_size, bar=bar)
    write_chunk(chunks, episode_id, rows)
    return len(rows)


def score_episode(fs: FrameSet, prepared: PreparedMatcher, episode_id: str, *, batch_size: int,
                  bar=None) -> pd.DataFrame:
    """One episode's rows, in the table's schema; ``bar`` counts frames."""
    ep = fs.episode(episode_id)
    frames = fs.frames[fs.frames.episode_id == episode_id].sort_values("step")
    prepared.hold(fs, ep.target_object_id)
    matcher, pool, workers = prepared.matcher, prepared.pool, prepared.workers
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
    return episode_rows(episode_id, str(ep.split), ids, frames.step.to_numpy(), results)
