"""Look-further stop policies by hand: the window, the candidates, the commit, the walk back counted, nothing after the
window read, the same rule without geometry and live inside the PIN detector."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from test_navigation import BACK, TARGET, table_of, walk_set  # noqa: F401 (walk_set: a fixture used below)
from test_policies import random_scored, scored_episodes

from pin_match.evaluation import EvalContext
from pin_match.evaluation.core.commits import commit_metrics, commitments, episode_stops, policy_metrics
from pin_match.evaluation.core.metrics import frame_arrays
from pin_match.evaluation.core.navigation import episodes_at
from pin_match.evaluation.core.policies import policy_sweep, tune_policy
from pin_match.evaluation.core.stop import (
    FIRST_MATCH,
    LookFurther,
    PolicyError,
    StopPolicy,
    found_frames,
    gated_scores,
    one_walk,
)
from pin_match.evaluation.pages.stop_page import stop_table


def test_policy_text_round_trips_and_bad_text_is_named():
    for text in ("look:20", "look:0", "look:20+0.1", "look:rest", "look:5@2-of-3", "look:rest+0.05"):
        assert str(StopPolicy.parse(text)) == text
    assert StopPolicy.parse("look:20+0.1") == LookFurther(window=20, clear=0.1)
    assert StopPolicy.parse("look:rest").upper_bound and not StopPolicy.parse("look:40").upper_bound
    with pytest.raises(PolicyError, match="look:W"):
        StopPolicy.parse("look:far")
    with pytest.raises(PolicyError, match="window of 0 frames or more"):
        LookFurther(window=-1)
    with pytest.raises(PolicyError, match="clear margin of 0 or more"):
        LookFurther(clear=-0.1)
    with pytest.raises(PolicyError, match="a look-further policy is not one gated score"):
        gated_scores(frame_arrays(scored_episodes({"e": "T"}, {"e": [0.5]})), LookFurther())


def test_it_looks_on_and_commits_to_the_best_candidate_of_its_window():
    # a look-alike fires first (step 1), the target later (step 4, higher); an unrelated frame in between
    scored = scored_episodes({"e": "OCGOTO"}, {"e": [0.1, 0.6, 0.55, 0.2, 0.8, 0.3]})
    arr = frame_arrays(scored)
    [pin] = FIRST_MATCH.decide(arr, 0.5)
    assert (pin.fired, pin.stop, pin.chosen) == (1, 1, 1)
    [short] = LookFurther(window=2).decide(arr, 0.5)  # steps 1-3: the look-alike beats the other frame
    assert (short.fired, short.stop, short.chosen, short.candidates) == (1, 3, 1, (1, 2))
    [long] = LookFurther(window=3).decide(arr, 0.5)  # steps 1-4: the target comes into the window
    assert (long.fired, long.stop, long.chosen, long.candidates) == (1, 4, 4, (1, 2, 4))
    [rest] = LookFurther(window=None).decide(arr, 0.5)  # to the walk's end
    assert (rest.stop, rest.chosen) == (5, 4)
    assert found_frames(arr, 0.5, LookFurther(window=3)).tolist() == [False] * 4 + [True, False]
    m = policy_metrics(scored, 0.5, LookFurther(window=3))
    assert m["first_match_precision"] == 100.0 and m["frames_to_first_match"] == 5.0 and m["frames_looked_at"] == 5.0
    assert policy_metrics(scored, 0.5)["frames_looked_at"] == 2.0  # PIN's rule commits where it fires


def test_a_candidate_that_clears_everything_before_commits_at_once():
    scored = scored_episodes({"e": "OCOTOO"}, {"e": [0.3, 0.55, 0.2, 0.9, 0.95, 0.3]})
    arr = frame_arrays(scored)
    # 0.55 clears the earlier best (0.3) by 0.25 only; 0.9 clears 0.55 by 0.35 >= 0.3: commit at step 3
    [d] = LookFurther(window=10, clear=0.3).decide(arr, 0.5)
    assert (d.fired, d.stop, d.chosen) == (1, 3, 3)
    [first] = LookFurther(window=10, clear=0.2).decide(arr, 0.5)  # the first candidate clears 0.3 by 0.25
    assert (first.stop, first.chosen) == (1, 1)
    [late] = LookFurther(window=10, clear=0.5).decide(arr, 0.5)  # nothing clears by 0.5: the window's end
    assert (late.stop, late.chosen) == (5, 4)


@pytest.mark.parametrize("seed", range(5))
def test_a_window_of_none_is_pin_s_rule(seed):
    arr = frame_arrays(random_scored(seed))
    for sigma in (0.2, 0.5, 0.8):
        for base in (StopPolicy(1, 1), StopPolicy(2, 3)):
            looked = LookFurther(base.k, base.n, window=0)
            assert looked.decide(arr, sigma) == base.decide(arr, sigma)
        first = np.zeros(len(arr.score), bool)
        fired = FIRST_MATCH.fires(arr, sigma)
        for start in np.flatnonzero(np.r_[True, np.diff(arr.episode) != 0]):
            hits = np.flatnonzero(fired[start:]) + start
            hits = hits[arr.episode[hits] == arr.episode[start]]
            first[hits[:1]] = True
        assert found_frames(arr, sigma, LookFurther(window=0)).tolist() == first.tolist()


@pytest.mark.parametrize("seed", range(8))
def test_nothing_after_the_commit_changes_the_decision(seed):
    rng = np.random.default_rng(seed)
    scored = random_scored(seed)
    arr = frame_arrays(scored)
    for policy in (LookFurther(window=3), LookFurther(window=5, clear=0.2), LookFurther(2, 3, window=4)):
        decisions = policy.decide(arr, 0.5)
        changed = arr.score.copy()
        starts = np.flatnonzero(np.r_[True, np.diff(arr.episode) != 0])
        ends = np.r_[starts[1:], len(changed)]
        for d, end in zip(decisions, ends):
            if d.stop is not None:
                changed[d.stop + 1:end] = rng.uniform(0, 2, end - d.stop - 1)  # later frames, even far above
        again = policy.decide(frame_arrays(scored.assign(score=changed)), 0.5)
        assert again == decisions


def test_a_live_walk_keeps_the_window_open_until_it_is_complete():
    scores = [0.1, 0.6, 0.2, 0.8]
    open_window = LookFurther(window=3).decide(one_walk(np.array(scores)), 0.5, walk_goes_on=True)[0]
    assert open_window.fired == 1 and open_window.stop is None and open_window.chosen is None
    done = LookFurther(window=2).decide(one_walk(np.array(scores)), 0.5, walk_goes_on=True)[0]
    assert (done.stop, done.chosen) == (3, 3)
    ended = LookFurther(window=3).decide(one_walk(np.array(scores)), 0.5)[0]  # a recording: the walk has ended
    assert (ended.stop, ended.chosen) == (3, 3)


def test_the_walk_back_and_the_frames_looked_on_are_counted(walk_set):  # noqa: F811 (the imported fixture)
    """test_navigation's walk: the look-alike 3 m to the camera's left at step 1, the target ahead; the agent walks
    to (1, 0) facing the target by step 5."""
    ctx = EvalContext(walk_set)
    places = ctx.placements(table_of(walk_set, [0.0, 0.9, 0.0, 0.0, 0.95, 0.0]), "val")
    pin = episodes_at(places, 0.5).iloc[0]
    assert (pin.outcome, pin.stop_step, pin.steps) == ("category error", 1, 1 + 0 + math.ceil((3 - BACK) / 0.25) + 1)
    look = episodes_at(places, 0.5, LookFurther(window=4)).iloc[0]  # steps 1-5: commits at step 5 to step 4
    assert (look.outcome, look.fired_step, look.stop_step, look.point_frame_id, look.candidates) == \
        ("success", 1, 5, "e_0004", 2)
    assert look.steps == 5 + 0 + 7 + 1  # walked to step 5, then 2 m ahead to stand BACK short of the target, stop
    assert look.path == pytest.approx(4.0 + 2.0 - BACK) and look.spl == pytest.approx(1.0)
    # the best candidate behind the agent: the look-alike (0.9) over a weaker target view; it walks back to it
    places = ctx.placements(table_of(walk_set, [0.0, 0.9, 0.0, 0.0, 0.6, 0.0]), "val")
    back = episodes_at(places, 0.5, LookFurther(window=None)).iloc[0]
    assert (back.outcome, back.stop_step, back.point_frame_id) == ("category error", 5, "e_0001")
    turn = math.degrees(math.atan2(3.0, -4.0))  # from (1, 0) facing 0 degrees to the look-alike at (-3, 3)
    assert back.steps == 5 + math.ceil((turn - 15) / 30) + math.ceil((5.0 - BACK) / 0.25) + 1
    stand = (-3.0 + 0.8 * BACK, 3.0 - 0.6 * BACK, 0.0)  # BACK short of the look-alike, toward (1, 0)
    assert back.path == pytest.approx(4.0 + 5.0 - BACK) and back.d2g == pytest.approx(math.dist(stand, TARGET))


def test_an_unplaced_candidate_is_passed_over_in_the_window_too(walk_set):  # noqa: F811
    # steps 0 and 3 see the target 6 m away (no depth in range); the look-alike at step 1 opens the window
    places = EvalContext(walk_set).placements(table_of(walk_set, [0.9, 0.6, 0.0, 0.95, 0.0, 0.0]), "val")
    stop = episodes_at(places, 0.5, LookFurther(window=2)).iloc[0]
    assert (stop.fired_step, stop.stop_step, stop.point_frame_id, stop.unplaced_firings, stop.candidates) == \
        (1, 3, "e_0001", 2, 1)


def test_without_geometry_it_says_what_it_committed_to():
    scored = scored_episodes({"a": "OCOT", "b": "CGOO", "c": "OOOO"},
                             {"a": [0.1, 0.6, 0.2, 0.8], "b": [0.7, 0.9, 0.1, 0.1], "c": [0.1] * 4})
    arr = frame_arrays(scored)
    rows = commitments(arr, 0.5, LookFurther(window=5)).set_index("episode_id")
    assert rows.loc["a", "committed_class"] == "TM" and rows.loc["a", "looked_frames"] == 4
    assert rows.loc["b", "committed_class"] == "GM" and rows.loc["b", "committed_step"] == 1
    assert pd.isna(rows.loc["c", "committed_class"]) and rows.loc["c", "looked_frames"] == 4
    m = commit_metrics(rows.reset_index())["metrics"]
    assert m["commit_target_pct"] == pytest.approx(100 / 3) and m["commit_other_pct"] == pytest.approx(100 / 3)
    assert m["commit_none_pct"] == pytest.approx(100 / 3) and m["commit_lookalike_pct"] == 0.0
    pin = commit_metrics(commitments(arr, 0.5, FIRST_MATCH))["metrics"]  # PIN's rule: a's look-alike, b's too
    assert pin["commit_lookalike_pct"] == pytest.approx(200 / 3)
    assert pin["frames_looked_at"] == pytest.approx((2 + 1 + 4) / 3)  # a and b commit at once, c looks at all 4
    stops = episode_stops(arr, 0.5, LookFurther(window=5)).set_index("episode_id")
    assert stops.loc["a", "candidates"] == "1:0.600; 3:0.800" and stops.loc["a", "commit_step"] == 3
    table = stop_table(episode_stops(arr, 0.5, LookFurther(window=5)), 0.5, LookFurther(window=5))
    assert table.loc["a", "committed to"] == "step 3, TM, 0.800" and table.loc["c", "committed at step"] == "never"


def test_sigma_is_tuned_for_a_look_further_policy_by_applying_each_sigma():
    scored = random_scored(3)
    policy = LookFurther(window=3)
    curve = policy_sweep(scored, policy)
    for _, row in curve.iloc[::7].iterrows():
        m = policy_metrics(scored, row["sigma"], policy)
        assert row["first_match_success"] == m["first_match_success"]


def test_report_and_bench_read_the_policy(walk_set, tmp_path):  # noqa: F811
    from pin_match.evaluation import report
    from pin_match.evaluation.core.tables import report_row

    table = table_of(walk_set, [0.0, 0.9, 0.0, 0.0, 0.95, 0.0])
    done = report(table, walk_set, tmp_path / "r", sigma=0.5, policy=LookFurther(window=4))
    assert done["policy"] == "look:4" and done["metrics"]["sr"] == 100.0 and done["metrics"]["steps"] == 13
    assert done["metrics"]["commit_target_pct"] == 100.0 and done["metrics"]["frames_looked_at"] == 6
    commits = pd.read_csv(tmp_path / "r" / "commits.csv")
    assert commits.loc[0, "committed_step"] == 4 and commits.loc[0, "policy"] == "look:4"
    assert report_row(done).name == "hand@0 look:4"
    page = (tmp_path / "r" / "report.html").read_text()
    assert "candidates (step:score)" in page and "fired at step 1, looked on to step 5" in page
    pin = report(table, walk_set, tmp_path / "r", sigma=0.5)
    assert pin["metrics"]["sr"] == 0.0 and not (tmp_path / "r" / "commits.csv").exists()


def test_tune_policy_chooses_sigma_for_the_window(walk_set):  # noqa: F811
    table = table_of(walk_set, [0.0, 0.9, 0.0, 0.0, 0.95, 0.0])
    # PIN's rule at any sigma up to 0.9 commits to the look-alike; only 0.95 reaches the target
    assert tune_policy(table, walk_set, FIRST_MATCH, objective="sr", split="val")["sigma"] == 0.95
    looked = tune_policy(table, walk_set, LookFurther(window=4), objective="sr", split="val")
    assert looked["policy"] == "look:4" and looked["objective_value"] == pytest.approx(100, abs=0.01)


def test_the_trade_reads_each_window_at_its_own_sigma(walk_set, tmp_path):  # noqa: F811
    from pin_match.evaluation.flows.trade import trade, write_trade

    table = table_of(walk_set, [0.0, 0.9, 0.0, 0.0, 0.95, 0.0])
    policies = [LookFurther(window=0), LookFurther(window=4), LookFurther(window=None)]
    rows = trade(EvalContext(walk_set), {"hand": table}, policies, tune_split="val", read_split="val")
    assert rows.policy.tolist() == ["look:0", "look:4", "look:rest"] and rows.upper_bound.tolist() == [0, 0, 1]
    assert rows.window.iloc[:2].tolist() == [0, 4] and math.isnan(rows.window.iloc[2])
    assert rows.sigma.tolist() == [0.95] * 3  # ties go to the highest sigma: only 0.95 passes the look-alike by
    # first match stops at step 4 (4 walked, 3 m ahead less BACK: 11 forward, stop); a window commits at step 5
    assert rows.steps.tolist() == [4 + 11 + 1, 5 + 7 + 1, 5 + 7 + 1] and rows.sr.tolist() == [100.0] * 3
    csv, png = write_trade(rows, tmp_path)
    assert pd.read_csv(csv).shape == rows.shape and png.stat().st_size > 0
