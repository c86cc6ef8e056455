"""PIN metrics on a hand-made table whose every number is worked out in the comments."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pin_match.evaluation.core.metrics import (
    MetricsError,
    auroc,
    average_precision,
    detection_metrics,
    frame_arrays,
    localisation_metrics,
    per_category,
)

# frame: (episode, step, category, target, same, other, seen, score)     class by PIN's precedence
HAND = [
    ("a0", "A", 0, "mug", 1, 0, 0, 1, 0.9),   # TM (seen)
    ("a1", "A", 1, "mug", 0, 1, 0, 0, 0.7),   # CM
    ("a2", "A", 2, "mug", 0, 0, 0, 0, 0.2),   # OM
    ("a3", "A", 3, "mug", 1, 1, 0, 0, 0.5),   # TM (target wins over the same-category distractor)
    ("b0", "B", 0, "mug", 0, 0, 1, 0, 0.8),   # GM
    ("b1", "B", 1, "mug", 1, 0, 0, 1, 0.6),   # TM (seen)
    ("b2", "B", 2, "mug", 0, 1, 1, 0, 0.6),   # CM (same-category wins over other)
    ("b3", "B", 3, "mug", 0, 0, 0, 0, 0.1),   # OM
    ("c0", "C", 0, "ball", 0, 0, 1, 0, 0.3),  # GM
    ("c1", "C", 1, "ball", 1, 0, 0, 0, 0.4),  # TM
]


def hand_scored(shuffle: bool = True) -> pd.DataFrame:
    df = pd.DataFrame(HAND, columns=["frame_id", "episode_id", "step", "target_category", "target_visible",
                                     "same_visible", "other_visible", "target_seen", "score"])
    for c in ("target_visible", "same_visible", "other_visible"):
        df[c] = df[c].astype(bool)
    df["target_seen"] = df["target_seen"].astype(float)
    df["split"] = "val"
    return df.sample(frac=1.0, random_state=3).reset_index(drop=True) if shuffle else df


def test_metrics_at_sigma_with_ties_counted_as_matched():
    m = detection_metrics(frame_arrays(hand_scored()), 0.6)
    # matched (score >= 0.6): a0 TM, a1 CM, b0 GM, b1 TM, b2 CM (b1, b2 tie at sigma) -> 5 frames
    assert (m["n_matched"], m["n_tm"], m["n_cm"], m["n_gm"], m["n_om"]) == (5, 2, 2, 1, 0)
    assert m["tm_pct"] == pytest.approx(40.0) and m["cm_pct"] == pytest.approx(40.0)
    assert m["nm_pct"] == pytest.approx(20.0) and m["gm_pct"] == pytest.approx(20.0) and m["om_pct"] == 0.0
    assert m["match_pct"] == pytest.approx(200 / 3)            # A, B matched; C's max is 0.4
    assert m["target_recall"] == pytest.approx(50.0)           # targets a0 a3 b1 c1; a0 b1 matched
    assert m["target_recall_seen"] == pytest.approx(100.0)     # seen: a0 b1, both matched
    assert m["false_positive_rate"] == pytest.approx(50.0)     # 3 of 6 non-target frames matched
    assert m["f1"] == pytest.approx(100 * 4 / 9)               # 2*2 / (5 matched + 4 targets)
    # first matched frame by step: A -> a0 (TM), B -> b0 (GM)
    assert m["n_first_tm"] == 1
    assert m["first_match_precision"] == pytest.approx(50.0)   # of the 2 matched episodes
    assert m["first_match_success"] == pytest.approx(100 / 3)  # of all 3 episodes


def test_ranking_metrics_by_hand():
    m = detection_metrics(frame_arrays(hand_scored()), 0.6)
    # target {.9 .5 .6 .4} vs rest {.7 .2 .8 .6 .1 .3}: pairs won 6 + 3 + 3.5 (tie at .6) + 3 = 15.5 of 24
    assert m["auroc_target"] == pytest.approx(15.5 / 24)
    # PR steps at .9 (1/1), .6 (2/5), .5 (3/6), .4 (4/7), each a quarter of recall
    assert m["ap_target"] == pytest.approx(0.25 * (1 + 2 / 5 + 3 / 6 + 4 / 7))
    # target vs same-category frames {.7 .6}: .9 wins 2, .6 ties once -> 2.5 of 8
    assert m["auroc_same"] == pytest.approx(2.5 / 8)
    # on {.9T .7N .6T .6N .5T .4T}: steps 1/1, 2/4, 3/5, 4/6
    assert m["ap_same"] == pytest.approx(0.25 * (1 + 2 / 4 + 3 / 5 + 4 / 6))


def test_no_matched_frame_is_undefined_not_zero():
    m = detection_metrics(frame_arrays(hand_scored()), 1.0)
    for key in ("tm_pct", "cm_pct", "nm_pct", "gm_pct", "om_pct", "first_match_precision"):
        assert m[key] is None, key
    assert m["match_pct"] == 0.0 and m["target_recall"] == 0.0 and m["first_match_success"] == 0.0


def test_all_frames_matched():
    m = detection_metrics(frame_arrays(hand_scored()), 0.0)
    # 10 matched: TM a0 a3 b1 c1, CM a1 b2, GM b0 c0, OM a2 b3; first frames a0 (TM), b0, c0 (GM)
    assert (m["tm_pct"], m["cm_pct"], m["gm_pct"], m["om_pct"], m["nm_pct"]) == pytest.approx((40, 20, 20, 20, 40))
    assert m["match_pct"] == 100.0 and m["target_recall"] == 100.0
    assert m["first_match_precision"] == pytest.approx(100 / 3)


def test_undefined_denominators():
    df = hand_scored()
    no_target = df[~df.target_visible]
    m = detection_metrics(frame_arrays(no_target), 0.6)
    assert m["target_recall"] is None and m["auroc_target"] is None and m["ap_target"] is None
    unknown_seen = df.assign(target_seen=np.where(df.frame_id == "a0", np.nan, df.target_seen))
    m = detection_metrics(frame_arrays(unknown_seen), 0.6)
    assert m["target_recall_seen"] is None and m["n_seen"] is None
    assert m["target_recall"] == pytest.approx(50.0)


def test_nan_score_is_rejected_naming_the_frame():
    df = hand_scored()
    df.loc[df.frame_id == "b2", "score"] = np.nan
    with pytest.raises(MetricsError, match="'b2'"):
        frame_arrays(df)


def test_duplicate_step_is_rejected():
    df = hand_scored()
    df.loc[df.frame_id == "a1", "step"] = 0
    with pytest.raises(MetricsError, match="episode 'A'"):
        frame_arrays(df)


def test_per_category():
    table = per_category(hand_scored(), 0.6)
    assert list(table.index) == ["ball", "mug"]
    mug, ball = table.loc["mug"], table.loc["ball"]
    # mug = episodes A, B: all 5 matched frames; targets a0 a3 b1 of which a0 b1 matched
    assert (mug.tm_pct, mug.cm_pct, mug.nm_pct, mug.match_pct) == pytest.approx((40, 40, 20, 100))
    assert mug.target_recall == pytest.approx(200 / 3) and mug.first_match_precision == pytest.approx(50)
    assert mug.n_episodes == 2
    # ball = episode C: nothing matched -> TM/CM/NM undefined, %Match and recall a defined 0
    assert math.isnan(ball.tm_pct) and math.isnan(ball.first_match_precision)
    assert ball.match_pct == 0.0 and ball.target_recall == 0.0
    assert ball.auroc_target == 1.0  # c1 (.4) above c0 (.3)


def test_auroc_and_ap_edge_cases():
    assert math.isnan(auroc(np.array([0.5]), np.array([])))
    assert auroc(np.array([1.0, 1.0]), np.array([1.0])) == 0.5
    assert math.isnan(average_precision(np.array([0.1, 0.2]), np.array([False, False])))
    # all tied: one step at recall 1 with precision 1/2
    assert average_precision(np.array([0.3, 0.3]), np.array([True, False])) == 0.5


def test_localisation_metrics():
    hits = pd.DataFrame(dict(frame_id=["x", "y", "z"], n_points=[2, 3, 0], n_on_target=[1, 0, 0],
                             hit=[True, False, False]))
    m = localisation_metrics(hits)
    assert m["localisation_accuracy"] == pytest.approx(100 / 3)       # 1 of 3 frames
    assert m["localisation_point_precision"] == pytest.approx(20.0)  # 1 of 5 points
    empty = localisation_metrics(hits.iloc[:0])
    assert empty["localisation_accuracy"] is None and empty["localisation_point_precision"] is None
