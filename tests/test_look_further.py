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
    for text in ("look:20", "look:0", "look:20+0.1", "look:rest (upper bound)", "look:5@2-of-3",
                 "look:rest+0.05 (upper bound)"):
        assert str(StopPolicy.parse(text)) == text
    assert StopPolicy.parse("look:20+0.1") == LookFurther(window=20, clear=0.1)
    assert StopPolicy.parse("look:rest").upper_bound and not StopPolicy.parse("look:40").upper_bound
    assert StopPolicy.parse("look:rest") == StopPolicy.parse("look:rest (upper bound)") == LookFurther(window=None)
    with pytest.raises(PolicyError, match="look:W"):
        StopPolicy.parse("look:far")
    with pytest.raises(PolicyError, match="look:W"):  # only the rest of the walk is the upper bound
        StopPolicy.parse("look:20 (upper bound)")
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
    [late] = LookFurther(window=4, clear=0.5).decide(arr, 0.5)  # nothing clears by 0.5: the window's end
    assert (late.stop, late.chosen) == (5, 4)
    [looking] = LookFurther(window=10, clear=0.5).decide(arr, 0.5)  # the window runs past the walk's end
    assert (looking.fired, looking.stop, looking.chosen, looking.candidates) == (1, None, None, (1, 3, 4))


@pytest.mark.parametrize("seed", range(5))
def test_a_window_of_zero_is_the_base_rule_in_every_reading(seed):
    """look:0 decides as its base window and PIN's metrics read it as the base: every firing is found, not the
    commit alone (issue 64, item 1)."""
    scored = random_scored(seed)
    arr = frame_arrays(scored)
    for sigma in (0.2, 0.5, 0.8):
        for base in (StopPolicy(1, 1), StopPolicy(2, 3)):
            looked = LookFurther(base.k, base.n, window=0)
            assert looked.decide(arr, sigma) == base.decide(arr, sigma)
            assert found_frames(arr, sigma, looked).tolist() == base.fires(arr, sigma).tolist()
            got, pin = policy_metrics(scored, sigma, looked), policy_metrics(scored, sigma, base)
            assert got.keys() == pin.keys()
            assert all(got[k] == pin[k] or (math.isnan(got[k]) and math.isnan(pin[k])) for k in pin), sigma


def test_look_zero_counts_every_firing_as_pin_s_rule_does_by_hand():
    # e: steps 1, 2 and 4 reach 0.5 (C, T, C): PIN's rule finds all three frames, so TM is 1 of 3 and CM 2 of 3
    scored = scored_episodes({"e": "OCTOCO"}, {"e": [0.1, 0.6, 0.7, 0.2, 0.9, 0.3]})
    m = policy_metrics(scored, 0.5, LookFurther(window=0))
    assert m["tm_pct"] == pytest.approx(100 / 3) and m["cm_pct"] == pytest.approx(200 / 3)
    assert m["first_match_precision"] == 0.0 and m["frames_to_first_match"] == 2.0
    # look:1 commits at step 2 to the target (0.7 beats 0.6); the firing at step 4 comes after the commit
    assert found_frames(frame_arrays(scored), 0.5, LookFurther(window=1)).tolist() == \
        [False, False, True, False, True, False]


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


def test_a_window_past_the_walk_s_end_is_still_looking_and_only_the_rest_commits_there():
    """Issue 64, item 1: a recording ends where an agent's walk would go on, so a window that reaches past its last
    frame commits to nothing (as live, where the window is still open); only look:rest, the upper bound, reads the
    recording's end and commits there."""
    scores = one_walk(np.array([0.1, 0.6, 0.2, 0.8]))
    [open_window] = LookFurther(window=3).decide(scores, 0.5)  # steps 1-4: the walk ends at step 3
    assert (open_window.fired, open_window.stop, open_window.chosen, open_window.candidates) == (1, None, None, (1, 3))
    [done] = LookFurther(window=2).decide(scores, 0.5)  # steps 1-3: closes on the last frame
    assert (done.stop, done.chosen) == (3, 3)
    [rest] = LookFurther(window=None).decide(scores, 0.5)
    assert (rest.stop, rest.chosen) == (3, 3)
    assert not found_frames(scores, 0.5, LookFurther(window=3)).any()


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
    assert (stop.fired_step, stop.stop_step, stop.point_frame_id, stop.unplaced_candidates, stop.candidates) == \
        (1, 3, "e_0001", 2, 1)


def test_without_geometry_it_says_what_it_committed_to():
    scored = scored_episodes({"a": "OCOT", "b": "CGOO", "c": "OOOO", "d": "OOCT"},
                             {"a": [0.1, 0.6, 0.2, 0.8], "b": [0.7, 0.9, 0.1, 0.1], "c": [0.1] * 4,
                              "d": [0.1, 0.1, 0.6, 0.9]})
    arr = frame_arrays(scored)
    look = LookFurther(window=2)  # a: steps 1-3, b: steps 0-2; d fires at step 2 and its window runs past step 3
    rows = commitments(arr, 0.5, look).set_index("episode_id")
    assert rows.loc["a", "committed_class"] == "TM" and rows.loc["a", "looked_frames"] == 4
    assert rows.loc["b", "committed_class"] == "GM" and rows.loc["b", "committed_step"] == 1
    assert rows.loc["b", "looked_frames"] == 3
    assert pd.isna(rows.loc["c", "committed_class"]) and rows.loc["c", "looked_frames"] == 4
    assert pd.isna(rows.loc["c", "fired_step"]) and rows.loc["c", "candidates"] == 0
    assert pd.isna(rows.loc["d", "committed_class"]) and rows.loc["d", "fired_step"] == 2
    assert rows.loc["d", "candidates"] == 2 and rows.loc["d", "looked_frames"] == 4
    m = commit_metrics(rows.reset_index())["metrics"]
    assert m["commit_target_pct"] == 25.0 and m["commit_other_pct"] == 25.0 and m["commit_lookalike_pct"] == 0.0
    assert m["commit_none_pct"] == 25.0 and m["still_looking_pct"] == 25.0
    assert m["frames_looked_at"] == pytest.approx((4 + 3 + 4 + 4) / 4)
    pin = commit_metrics(commitments(arr, 0.5, FIRST_MATCH))["metrics"]  # PIN's rule: a's, b's and d's look-alike
    assert pin["commit_lookalike_pct"] == 75.0 and pin["still_looking_pct"] == 0.0
    assert pin["frames_looked_at"] == pytest.approx((2 + 1 + 4 + 3) / 4)  # c looks at all 4
    stops = episode_stops(arr, 0.5, look).set_index("episode_id")
    assert stops.loc["a", "candidates"] == "1:0.600; 3:0.800" and stops.loc["a", "commit_step"] == 3
    table = stop_table(episode_stops(arr, 0.5, look), 0.5, look)
    assert table.loc["a", "committed to"] == "step 3, TM, 0.800" and table.loc["c", "committed at step"] == "never"
    assert table.loc["d", "committed at step"] == "still looking at the walk's end"


def test_sigma_is_tuned_for_a_look_further_policy_by_hand():
    """policy_sweep against a hand count. look:1 commits to the better of the first firing and the frame after it;
    the frames found are the committed one and every firing after the commit (as PIN's rule finds every firing).
    e1 O C T O (0.1 0.6 0.8 0.3), e2 T O C O (0.7 0.2 0.9 0.4); per sigma (each distinct score), the frames found
    and the episodes whose first found frame is the target:
    0.1  e1 commits at step 1 to C (0.6 > 0.1): C, T, O; e2 commits to T at step 1: T, C, O        -> 1 of 2
    0.2  e1 fires at 1 and commits to T (0.8): T, O; e2 T, C, O                                        -> 2 of 2
    0.3  the same frames (0.3 fires after e1's commit, 0.2 no longer fires)                            -> 2 of 2
    0.4  e1 T; e2 T, C, O (0.4 reaches 0.4)                                                             -> 2 of 2
    0.6  e1 T; e2 T, C                                                                                 -> 2 of 2
    0.7  e1 fires at 2 only: T; e2 T, C                                                                -> 2 of 2
    0.8  e1 T; e2 fires at 2 only: C                                                                   -> 1 of 2
    0.9  e1 never fires; e2 C                                                                          -> 0 of 2"""
    scored = scored_episodes({"e1": "OCTO", "e2": "TOCO"}, {"e1": [0.1, 0.6, 0.8, 0.3], "e2": [0.7, 0.2, 0.9, 0.4]})
    curve = policy_sweep(scored, LookFurther(window=1))
    assert curve["sigma"].tolist() == [0.1, 0.2, 0.3, 0.4, 0.6, 0.7, 0.8, 0.9]
    assert curve["n_matched"].tolist() == [6, 5, 5, 4, 3, 3, 2, 1]
    assert curve["n_first_tm"].tolist() == [1, 2, 2, 2, 2, 2, 1, 0]
    assert curve["n_matched_episodes"].tolist() == [2, 2, 2, 2, 2, 2, 2, 1]
    assert curve["n_tm"].tolist() == [2, 2, 2, 2, 2, 2, 1, 0]
    assert curve["first_match_success"].tolist() == [50.0, 100.0, 100.0, 100.0, 100.0, 100.0, 50.0, 0.0]


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


def test_a_report_says_where_the_agent_is_still_looking_and_labels_the_upper_bound(walk_set, tmp_path):  # noqa: F811
    """At 0.95 look:4 fires on the target at step 4 of 6: its window runs past the walk's end, so it is not found for
    SR and the tables give it its own share; look:rest commits at the end and every table says it is the upper
    bound."""
    from pin_match.evaluation import report
    from pin_match.evaluation.core.tables import report_row

    table = table_of(walk_set, [0.0, 0.9, 0.0, 0.0, 0.95, 0.0])
    done = report(table, walk_set, tmp_path / "r", sigma=0.95, policy=LookFurther(window=4))
    assert done["metrics"]["sr"] == 0.0 and done["metrics"]["not_found_pct"] == 100.0
    assert done["metrics"]["still_looking_pct"] == 100.0 and done["metrics"]["commit_none_pct"] == 0.0
    walks = pd.read_csv(tmp_path / "r" / "navigation.csv")
    assert walks.loc[0, "outcome"] == "not found" and walks.loc[0, "fired_step"] == 4
    page = (tmp_path / "r" / "report.html").read_text()
    assert "Still looking" in page and "still looking: the window opened at step 4 ran past the walk" in page
    rest = report(table, walk_set, tmp_path / "rest", sigma=0.95, policy=LookFurther(window=None))
    assert rest["metrics"]["sr"] == 100.0 and rest["policy"] == "look:rest (upper bound)"
    assert report_row(rest).name == "hand@0 look:rest (upper bound)"
    assert pd.read_csv(tmp_path / "rest" / "commits.csv").loc[0, "policy"] == "look:rest (upper bound)"
    assert "look:rest (upper bound)" in (tmp_path / "rest" / "report.html").read_text()


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
    assert rows.policy.tolist() == ["look:0", "look:4", "look:rest (upper bound)"]
    assert rows.upper_bound.tolist() == [0, 0, 1]
    assert rows.window.iloc[:2].tolist() == [0, 4] and math.isnan(rows.window.iloc[2])
    # ties go to the highest sigma: only 0.95 passes the look-alike by under PIN's rule and to the walk's end; look:4
    # at 0.95 opens its window at step 4, which runs past the walk's last step (5): still looking, so 0.9, which
    # opens it at step 1 and sees the target at step 4
    assert rows.sigma.tolist() == [0.95, 0.9, 0.95] and rows.still_looking_pct.tolist() == [0.0] * 3
    # first match stops at step 4 (4 walked, 3 m ahead less BACK: 11 forward, stop); a window commits at step 5
    assert rows.steps.tolist() == [4 + 11 + 1, 5 + 7 + 1, 5 + 7 + 1] and rows.sr.tolist() == [100.0] * 3
    csv, png = write_trade(rows, tmp_path)
    assert pd.read_csv(csv).shape == rows.shape and png.stat().st_size > 0
