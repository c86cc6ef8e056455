"""One interval definition: target instances resampled, shared by a report's intervals and the paired ones."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_metrics import hand_scored

from pin_match.evaluation.core.intervals import (
    bootstrap_ci,
    episode_weights,
    instance_clusters,
    percentile_interval,
    unit_codes,
    wilson_interval,
)
from pin_match.evaluation.core.metrics import Bootstrap, detection_metrics, frame_arrays, ranking_metrics


def test_bootstrap_is_seeded_and_honours_undefined():
    df = hand_scored()
    a = bootstrap_ci(df, 0.6, boot=Bootstrap(n_boot=200, seed=1))
    assert a == bootstrap_ci(df, 0.6, boot=Bootstrap(n_boot=200, seed=1))
    lo, hi = a["tm_pct"]
    assert 0.0 <= lo <= hi <= 100.0
    assert bootstrap_ci(df, 1.0, boot=Bootstrap(n_boot=50))["tm_pct"] is None  # undefined in every resample
    one = df[df.episode_id == "A"]  # a single episode: every resample is the same -> a point interval
    # A at 0.6: a0 TM, a1 CM -> 50 %
    assert bootstrap_ci(one, 0.6, boot=Bootstrap(n_boot=20))["tm_pct"] == [50.0, 50.0]


def test_episodes_of_one_instance_are_drawn_together():
    df = hand_scored()
    arr = frame_arrays(df)
    point = {**detection_metrics(arr, 0.6), **ranking_metrics(arr)}
    # one instance behind all three episodes: every resample holds each episode once -> point intervals
    together = bootstrap_ci(df, 0.6, clusters=dict(A="x", B="x", C="x"), boot=Bootstrap(n_boot=50))
    for key in ("tm_pct", "cm_pct", "match_pct", "first_match_success", "auroc_target", "auroc_same"):
        assert together[key] == pytest.approx([point[key], point[key]]), key
    # each episode its own unit: %Match at 0.6 is 2/4, 3/4 and 0/2 in A, B and C, so the draws spread it
    apart = bootstrap_ci(df, 0.6, boot=Bootstrap(n_boot=200))
    assert apart["match_pct"][0] < point["match_pct"] < apart["match_pct"][1]


def test_units_and_weights_by_hand():
    assert unit_codes(["e1", "e2", "e3"], {"e1": "mug", "e2": "cup", "e3": "mug"}).tolist() == [0, 1, 0]
    assert unit_codes(["e1", "e2"], None).tolist() == [0, 1]
    codes = np.array([0, 1, 0])
    for weights in episode_weights(codes, Bootstrap(n_boot=30, seed=4)):
        assert weights[0] == weights[2] and weights[0] + weights[1] == 2.0  # 2 units drawn, mugs together
    rng = np.random.default_rng(4)  # the draw is numpy's generator on the unit count, as documented
    first = next(episode_weights(codes, Bootstrap(n_boot=1, seed=4)))
    assert first.tolist() == np.bincount(rng.integers(0, 2, 2), minlength=2)[codes].astype(float).tolist()


def test_percentile_interval_leaves_undefined_resamples_out():
    assert percentile_interval(np.array([1.0, np.nan, 3.0]), 1.0) == (1.0, 3.0)
    assert all(math.isnan(v) for v in percentile_interval(np.array([np.nan]), 0.95))


def test_instance_clusters_read_the_episodes_table(tiny_frameset):
    clusters = instance_clusters(tiny_frameset.episodes)
    assert clusters == dict(zip(tiny_frameset.episodes.episode_id, tiny_frameset.episodes.target_object_id))


def test_wilson_interval_matches_hand_computed_values():
    z = 1.959963984540054
    assert wilson_interval(0, 4, 0.95) == pytest.approx((0.0, z * z / (4 + z * z)))  # 0-0.490
    assert wilson_interval(4, 4, 0.95) == pytest.approx((4 / (4 + z * z), 1.0))
    assert wilson_interval(1, 4, 0.95) == pytest.approx((0.04559, 0.69936), abs=1e-5)  # 1 of 4: 4.6-69.9 %
    assert all(math.isnan(b) for b in wilson_interval(0, 0, 0.95))


def test_a_share_of_episodes_at_its_bound_gets_wilsons_interval():
    """Above every score no episode matches: each resample repeats 0 %, so %Match and first-match success get
    Wilson's interval over the 3 episodes (0 to z^2 / (3 + z^2)); below every score all 3 match."""
    z2 = 1.959963984540054 ** 2
    none = bootstrap_ci(hand_scored(), 0.95)
    assert none["match_pct"] == pytest.approx([0.0, 100 * z2 / (3 + z2)])
    assert none["first_match_success"] == pytest.approx([0.0, 100 * z2 / (3 + z2)])
    every = bootstrap_ci(hand_scored(), 0.0)
    assert every["match_pct"] == pytest.approx([100 * 3 / (3 + z2), 100.0])
    assert every["first_match_success"][0] < 100 / 3 < every["first_match_success"][1]  # 1 of 3: percentile
