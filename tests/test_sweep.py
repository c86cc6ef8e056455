"""The vectorised sweep equals the per-threshold loop exactly, and the metrics at sampled sigmas."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pin_match.evaluation.core.metrics import COUNT_KEYS, METRIC_KEYS, detection_metrics, frame_arrays
from pin_match.evaluation.core.sweep import sweep, sweep_loop


def random_scored(seed: int, n: int = 500, episodes: int = 40, levels: int | None = None,
                  seen_unknown: bool = False) -> pd.DataFrame:
    """Random frames in random order; ``levels`` quantises scores so ties are common."""
    rng = np.random.default_rng(seed)
    ep = rng.integers(0, episodes, n)
    df = pd.DataFrame(dict(frame_id=[f"f{i}" for i in range(n)], episode_id=[f"e{x}" for x in ep],
                           step=rng.permutation(n), target_category=[f"c{x % 3}" for x in ep]))
    df["target_visible"] = rng.random(n) < 0.2
    df["same_visible"] = rng.random(n) < 0.3
    df["other_visible"] = rng.random(n) < 0.3
    df["target_seen"] = (df.target_visible & (rng.random(n) < 0.5)).astype(float)
    if seen_unknown:
        df.loc[0, "target_seen"] = np.nan
    df["score"] = rng.integers(0, levels, n) / levels if levels else rng.random(n)
    return df


@pytest.mark.parametrize("seed,levels,seen_unknown", [(0, None, False), (1, 7, False), (2, 40, True),
                                                      (3, 2, False), (4, None, True)])
def test_sweep_equals_loop_exactly(seed, levels, seen_unknown):
    df = random_scored(seed, levels=levels, seen_unknown=seen_unknown)
    fast, slow = sweep(frame_arrays(df)), sweep_loop(frame_arrays(df))
    assert len(fast) == df.score.nunique()
    pd.testing.assert_frame_equal(fast, slow, check_exact=True, check_dtype=False)


def test_sweep_matches_detection_metrics_at_sampled_sigmas():
    df = random_scored(5, levels=25)
    arr = frame_arrays(df)
    table = sweep(arr).set_index("sigma")
    for sigma in table.index[::5]:
        m = detection_metrics(arr, sigma)
        for key in (*COUNT_KEYS, *METRIC_KEYS):
            expected = table.loc[sigma, key]
            assert (m[key] is None) == np.isnan(expected), key
            if m[key] is not None:
                assert m[key] == expected, key


def test_first_match_when_a_later_record_is_the_target():
    # one episode, step order: .5 (other), .3 (nothing), .9 (target), .7 (target)
    # records (beat every earlier score): .5 then .9. sigma .9 -> first match = the target frame;
    # sigma .7 -> still the .9 frame (.7 comes later); sigma .5 and below -> the .5 frame (not TM)
    df = pd.DataFrame(dict(frame_id=list("pqrs"), episode_id="E", step=[0, 1, 2, 3], target_category="mug",
                           target_visible=[False, False, True, True], same_visible=False,
                           other_visible=[True, False, False, False], target_seen=0.0, score=[.5, .3, .9, .7]))
    table = sweep(frame_arrays(df)).set_index("sigma")
    assert list(table.n_first_tm) == [0, 0, 1, 1]  # sigma .3 .5 .7 .9
    assert list(table.match_pct) == [100.0] * 4
    assert list(table.tm_pct) == [50.0, pytest.approx(200 / 3), 100.0, 100.0]


def test_sweep_of_nothing_is_empty():
    arr = frame_arrays(random_scored(0).iloc[:0])
    assert sweep(arr).empty and sweep_loop(arr).empty
