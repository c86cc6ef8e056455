"""Threshold sweep speed: every metric at every distinct sigma versus one pass per threshold.

The per-threshold loop is timed on a sample of thresholds only (the full loop over a
million thresholds would take days) and extrapolated linearly to all of them, since each
of its iterations costs the same full pass over the frames; the result says so.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from benchmarks.timing import fastest, once
from pin_match.evaluation.core.metrics import frame_arrays
from pin_match.evaluation.core.sweep import sweep, sweep_loop


def synthetic_scored(n_frames: int, n_episodes: int, seed: int = 0) -> pd.DataFrame:
    """Random scored frames, ordered by episode and step as score tables are."""
    rng = np.random.default_rng(seed)
    episode = np.sort(rng.integers(0, n_episodes, n_frames))
    starts = np.r_[0, np.flatnonzero(np.diff(episode)) + 1]
    step = np.arange(n_frames) - np.repeat(starts, np.diff(np.r_[starts, n_frames]))
    target = rng.random(n_frames) < 0.1
    return pd.DataFrame(dict(
        frame_id=np.arange(n_frames).astype(str), episode_id=pd.Categorical(episode.astype(str)), step=step,
        target_category=np.asarray([f"c{i}" for i in range(18)])[episode % 18],
        target_visible=target, same_visible=rng.random(n_frames) < 0.15, other_visible=rng.random(n_frames) < 0.3,
        target_seen=(target & (rng.random(n_frames) < 0.5)).astype(float),
        score=rng.random(n_frames) + 0.3 * target))


def run(quick: bool = False) -> dict:
    n_frames, n_episodes, n_loop = (100_000, 3_000, 5) if quick else (1_000_000, 30_000, 10)
    df = synthetic_scored(n_frames, n_episodes)
    sweep(frame_arrays(df.iloc[:1000]))  # warm-up: imports and first-call overheads
    got: dict = {}  # what the timed calls return
    t_sweep = fastest({"sweep": lambda: got.update(curve=sweep(frame_arrays(df)))}, repeats=3)["sweep"].wall_s
    t_prepare = once(lambda: got.update(arrays=frame_arrays(df))).wall_s
    curve = got["curve"]
    sample = curve["sigma"].to_numpy()[np.linspace(0, len(curve) - 1, n_loop).astype(int)]
    t_loop = once(lambda: got.update(loop=sweep_loop(got["arrays"], sample))).wall_s
    loop = got["loop"]
    same = curve.set_index("sigma").loc[sample].reset_index()
    pd.testing.assert_frame_equal(same, loop, check_exact=True, check_dtype=False)
    per_threshold = t_loop / n_loop
    extrapolated = per_threshold * len(curve) + t_prepare
    result = dict(n_frames=n_frames, n_episodes=n_episodes, n_thresholds=len(curve), sweep_s=t_sweep,
                  loop_thresholds_timed=n_loop, loop_per_threshold_s=per_threshold,
                  loop_all_thresholds_s_extrapolated=extrapolated, ratio_extrapolated=extrapolated / t_sweep)
    print(f"sweep: {n_frames:,} frames, {n_episodes:,} episodes, {len(curve):,} distinct sigmas: "
          f"{t_sweep:.3f} s (best of 3)")
    print(f"per-threshold loop: {per_threshold * 1000:.1f} ms per sigma (timed on {n_loop}, equal to the sweep there); "
          f"all {len(curve):,} sigmas extrapolated: {extrapolated:,.0f} s = {result['ratio_extrapolated']:,.0f}x "
          f"the sweep")
    return result


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
