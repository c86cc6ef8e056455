"""House-relative stops by hand: the level, the line, what they assume (the target not among the frames that set the
level) and the page that explains them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_navigation import table_of, walk_set  # noqa: F401 (walk_set: a fixture used below)
from test_policies import scored_episodes

from pin_match.evaluation.core.commits import episode_stops, policy_metrics
from pin_match.evaluation.core.metrics import frame_arrays
from pin_match.evaluation.core.stop import (
    FIRST_MATCH,
    HouseStop,
    LookFurther,
    PolicyError,
    RunningLevel,
    StopPolicy,
    found_frames,
    gated_scores,
    house_level,
    one_walk,
)
from pin_match.evaluation.pages.stop_page import stop_html, stop_table


def test_the_house_level_is_the_mean_of_the_highest_earlier_scores_of_the_episode():
    arr = frame_arrays(scored_episodes({"e1": "GCOT", "e2": "OT"}, {"e1": [0.2, 0.5, 0.3, 0.9], "e2": [0.7, 0.4]}))
    level = house_level(arr, top=2)
    # e1: nothing before step 0; then {0.2}; {0.5, 0.2}; the two highest of {0.2, 0.5, 0.3}; e2 starts afresh
    assert np.isnan(level[0]) and np.isnan(level[4])
    assert level[[1, 2, 3, 5]] == pytest.approx([0.2, 0.35, 0.4, 0.7])
    assert house_level(arr, top=1)[[1, 2, 3]] == pytest.approx([0.2, 0.5, 0.5])  # the running maximum


def test_a_frame_counts_above_sigma_and_the_house_level_plus_the_margin():
    # e1: others at 0.5, a look-alike at 0.6, the target at 0.8: the look-alike clears sigma 0.3 but not
    # 0.5 + 0.15, the target clears 0.6 + 0.15 (running maximum: top 1)
    scored = scored_episodes({"e1": "GGCT"}, {"e1": [0.5, 0.5, 0.6, 0.8]})
    arr = frame_arrays(scored)
    house = HouseStop(top=1, margin=0.15)
    assert found_frames(arr, 0.3, house).tolist() == [True, False, False, True]  # step 0: no level, sigma alone
    assert found_frames(arr, 0.55, house).tolist() == [False, False, False, True]
    assert found_frames(arr, 0.3, FIRST_MATCH).tolist() == [True] * 4
    assert gated_scores(arr, house).tolist() == [0.5, -np.inf, -np.inf, 0.8]
    m = policy_metrics(scored, 0.55, house)
    assert m["first_match_precision"] == 100.0 and m["cm_pct"] == 0.0 and m["frames_to_first_match"] == 4.0


def test_a_level_shift_between_houses_moves_pin_s_sigma_but_not_the_house_line():
    """Two houses of one pattern (others, look-alike, target), the second 0.3 higher: one sigma cannot serve both
    (0.65 fires on the second house's others), the house-relative line can (sigma 0.3, margin 0.15)."""
    low = [0.2, 0.25, 0.35, 0.6]
    scored = scored_episodes({"a": "GOCT", "b": "GOCT"}, {"a": low, "b": [s + 0.3 for s in low]})
    arr = frame_arrays(scored)
    assert found_frames(arr, 0.5, FIRST_MATCH).tolist() == [False, False, False, True, True, True, True, True]
    house = HouseStop(top=1, margin=0.15)
    assert found_frames(arr, 0.3, house).tolist() == [False, False, False, True, True, False, False, True]
    # the first frame of house b fires on sigma alone: no earlier frame sets a level there


def test_a_walk_that_starts_facing_the_target_raises_the_level_over_the_target():
    """The target in the first frames: its own scores set the level, so a later, better view of it must beat itself
    by the margin; with sigma above the first view nothing fires."""
    scored = scored_episodes({"e": "TTTCO"}, {"e": [0.7, 0.72, 0.8, 0.5, 0.1]})
    arr = frame_arrays(scored)
    assert not found_frames(arr, 0.75, HouseStop(top=1, margin=0.1)).any()
    assert found_frames(arr, 0.75, FIRST_MATCH).tolist() == [False, False, True, False, False]
    assert found_frames(arr, 0.6, HouseStop(top=1, margin=0.1)).tolist() == [True, False, False, False, False]


def test_a_look_alike_before_the_target_sets_the_line_the_target_must_clear():
    scored = scored_episodes({"e": "OCOTT"}, {"e": [0.1, 0.6, 0.1, 0.65, 0.8]})
    arr = frame_arrays(scored)
    # the look-alike clears the house (0.1 + 0.4) and fires: the rule is relative to what came before, not a verifier
    assert found_frames(arr, 0.2, HouseStop(top=1, margin=0.4)).tolist() == [False, True, False, False, False]
    # a margin above the look-alike's lead over the house (0.5) keeps it below its line, but the target must then beat
    # the look-alike by as much (0.8 < 0.6 + 0.55): nothing fires
    assert not found_frames(arr, 0.2, HouseStop(top=1, margin=0.55)).any()


def test_policy_text_round_trips_and_bad_text_is_named():
    for text in ("house:top3+0.1", "house:top1-0.05", "house:top5+0@2-of-3", "2-of-3"):
        assert str(StopPolicy.parse(text)) == text
    assert StopPolicy.parse("house:top3+0.1") == HouseStop(top=3, margin=0.1)
    assert StopPolicy.parse("house:top5+0@2-of-3") == HouseStop(2, 3, top=5, margin=0.0)
    with pytest.raises(PolicyError, match="house:topT"):
        StopPolicy.parse("house:max+0.1")
    with pytest.raises(PolicyError, match="top >= 1"):
        HouseStop(top=0)
    with pytest.raises(PolicyError, match="window of 3 frames"):
        gated_scores(frame_arrays(scored_episodes({"e": "T"}, {"e": [0.5]})), StopPolicy(2, 3))


NUMBERS = st.floats(min_value=0.0, allow_nan=False, allow_infinity=False)
WINDOWS = st.tuples(st.integers(1, 9), st.integers(0, 9)).map(lambda kn: (kn[0], kn[0] + kn[1]))


@given(top=st.integers(1, 50), margin=st.one_of(NUMBERS, NUMBERS.map(lambda x: -x)), window=WINDOWS)
def test_the_text_of_a_house_policy_reads_back_as_the_same_policy(top, margin, window):
    """Issue 66: house:top3+0.1234567 printed as +0.123457 and read back as another policy (the index page reads the
    printed text back)."""
    policy = HouseStop(*window, top=top, margin=margin)
    assert StopPolicy.parse(str(policy)) == policy


@given(look=st.one_of(st.none(), st.integers(0, 10_000)), clear=st.one_of(st.none(), NUMBERS), window=WINDOWS)
def test_the_text_of_a_look_further_policy_reads_back_as_the_same_policy(look, clear, window):
    policy = LookFurther(*window, window=look, clear=clear)
    assert StopPolicy.parse(str(policy)) == policy


def test_the_printed_text_keeps_every_digit():
    assert str(StopPolicy.parse("look:20+0.1234567")) == "look:20+0.1234567"
    assert str(HouseStop(top=3, margin=-1 / 3)) == "house:top3-0.3333333333333333"
    assert str(StopPolicy.parse("house:top5+0@2-of-3")) == "house:top5+0@2-of-3"  # a whole number stays whole


@pytest.mark.parametrize("text", ["look:20@0-of-3", "house:top3+0.1@4-of-3", "look:rest+0.1@0-of-2"])
def test_a_bad_base_window_is_refused_naming_the_whole_policy(text):
    """Issue 66: look:20@0-of-3 was refused as "stop policy 0-of-3", which is not what the user wrote."""
    with pytest.raises(PolicyError, match="need 1 <= k <= n") as refused:
        StopPolicy.parse(text)
    assert str(refused.value).startswith(f"stop policy {text}")


def test_each_episode_says_where_the_line_was_and_why():
    scored = scored_episodes({"e1": "GGCT", "e2": "OCOO"}, {"e1": [0.5, 0.5, 0.6, 0.8], "e2": [0.1, 0.7, 0.2, 0.1]})
    arr = frame_arrays(scored)
    house = HouseStop(top=1, margin=0.15)
    stops = episode_stops(arr, 0.55, house).set_index("episode_id")
    e1, e2 = stops.loc["e1"], stops.loc["e2"]
    assert (e1.first_step, e1.first_class, e1.stop_step, e1.stop_class) == (2, "CM", 3, "TM")
    assert e1.stop_level == pytest.approx(0.6) and e1.stop_line == pytest.approx(0.75)
    assert (e1.peak_step, e1.peak_score) == (3, 0.8) and e1.peak_offset == pytest.approx(0.2)
    assert (e2.first_step, e2.stop_step, e2.stop_class) == (1, 1, "CM")  # 0.7 clears 0.1 + 0.15 and sigma
    assert e2.peak_step is None or math.isnan(e2.peak_step)  # no target frame in e2
    table = stop_table(episode_stops(arr, 0.55, house), 0.55, house)
    assert table.loc["e1", "why"] == "fired: 0.800 reached level 0.600 + margin 0.15, above sigma"
    assert table.loc["e2", "why"] == "fired: 0.700 reached sigma 0.55, above level + margin (0.250)"
    assert table.loc["e1", "first match (PIN's rule)"] == "step 2, CM, 0.600"
    never = stop_table(episode_stops(arr, 0.9, house), 0.9, house)
    assert never.loc["e1", "why"] == "never fired; the target's best 0.800 is below sigma 0.9"
    assert never.loc["e2", "why"] == "never fired; the target is never in view"
    page = "".join(stop_html(arr, 0.55, house))
    assert 'id="stop"' in page and "house:top1+0.15" in page and "reached level 0.600" in page
    assert "no house level is read" in "".join(stop_html(arr, 0.55))


def test_the_walk_stops_where_the_house_relative_policy_fires(walk_set):  # noqa: F811 (the imported fixture)
    """The recorded walk (test_navigation): the look-alike at step 1 clears sigma, so PIN's rule walks to it; the house
    line (the running maximum plus 0.3) keeps it out and stops at step 4, the target 3 m ahead."""
    from pin_match.evaluation import EvalContext
    from pin_match.evaluation.core.navigation import episodes_at

    places = EvalContext(walk_set).placements(table_of(walk_set, [0.3, 0.5, 0.2, 0.35, 0.9, 0.95]), "val")
    pin = episodes_at(places, 0.4).iloc[0]
    house = episodes_at(places, 0.4, HouseStop(top=1, margin=0.3)).iloc[0]
    assert (pin.outcome, pin.stop_step) == ("category error", 1)
    assert (house.outcome, house.stop_step, house.point_frame_id) == ("success", 4, "e_0004")


def test_the_candidates_passed_over_are_counted_once_each():
    """Issue 66: ``Decision.unplaced`` counted firings before the window and distinct candidates inside it. Under
    2-of-3, steps 1 and 2 fire for the same candidate (step 1, the latest counted frame): one candidate passed over."""
    walk = one_walk(np.array([0.9, 0.9, 0.1, 0.1, 0.1, 0.9, 0.9, 0.1]))
    unplaceable = {1}.__contains__
    [pin] = StopPolicy(2, 3).decide(walk, 0.5, lambda frame: not unplaceable(frame))
    assert (pin.fired, pin.chosen, pin.unplaced) == (6, 6, 1)
    [look] = LookFurther(2, 3, window=1).decide(walk, 0.5, lambda frame: not unplaceable(frame))
    assert (look.fired, look.stop, look.chosen, look.unplaced) == (6, 7, 6, 1)
    # inside the window too: 1-of-1, steps 0, 1 and 5, 6 fire; 0 opens the window of 6 frames, 1 and 5 cannot be
    # placed, each counted once
    [inside] = LookFurther(window=6).decide(walk, 0.5, lambda frame: frame not in (1, 5))
    assert (inside.fired, inside.stop, inside.candidates, inside.unplaced) == (0, 6, (0, 6), 2)


@pytest.mark.parametrize("top", [1, 3, 7, 12])
def test_the_running_level_an_agent_keeps_equals_the_house_level(top):
    """The live detector keeps the house's level step by step (``RunningLevel``) instead of reading the whole walk
    at every step; ``house_level`` is the definition, and the two agree exactly on a long walk with ties."""
    rng = np.random.default_rng(top)
    scores = np.round(rng.uniform(size=1500), 2)  # rounded: many ties
    running, levels = RunningLevel(top), []
    for score in scores:
        levels.append(running.level)
        running.add(score)
    expected = house_level(one_walk(scores), top)
    assert np.array_equal(np.array(levels), expected, equal_nan=True)
    assert np.isnan(RunningLevel(None).level)
