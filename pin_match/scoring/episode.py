"""One episode's rows: the per-episode step that the local runner and the Dask runner share.

The target is prepared once per episode (or kept from the previous episode of the same
target), frames are decoded ahead of the matcher in a thread pool, and the rows come back
in step order; the caller writes them as the episode's chunk.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pandas as pd

from pin_match.contract.matcher import Matcher, MatcherError, MatchResult
from pin_match.data.frameset import FrameSet


def score_episode(fs: FrameSet, matcher: Matcher, episode_id: str, *, batch_size: int, pool: ThreadPoolExecutor,
                  workers: int = 1, bar=None, held: dict[str, str] | None = None) -> pd.DataFrame:
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
