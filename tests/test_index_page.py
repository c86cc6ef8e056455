"""The index page's sentences about a paired comparison, from a hand-made comparison table."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pin_match.evaluation.flows.compare import Comparison
from pin_match.evaluation.flows.index_page import (
    closed_loop_caption,
    closed_loop_line,
    comparison_lines,
    roles_line,
    shown_episodes,
    sight_line,
    stop_line,
)


def _comparison(fm_prec_diff: float, fm_prec_ci: tuple[float, float] = (-5.0, 25.0)) -> Comparison:
    diff = "color@1 - verify@2"
    paired = pd.DataFrame({diff: [fm_prec_diff, 0.143, 0.151], "CI low": [np.nan if np.isnan(fm_prec_diff) else
                                                                          fm_prec_ci[0], 0.001, -0.001],
                           "CI high": [np.nan if np.isnan(fm_prec_diff) else fm_prec_ci[1], 0.277, 0.269]},
                          index=["FM-prec", "AUROC-same", "AUROC"])
    test = dict(only_a=0, only_b=1, both=0, p_value=1.0)
    return Comparison(("verify@2", "color@1"), paired, test, [], None)


def test_a_difference_neither_side_can_have_is_said_so_not_printed_as_nan():
    """FM-prec is undefined when one matcher matched no episode: the sentence says so instead of '+nan'."""
    line = comparison_lines(_comparison(float("nan")))[0]
    assert "nan" not in line
    assert line.startswith("color minus verify: FM-prec n/a (one of them matched no episode); AUROC-same +0.143 "
                           "(95 % CI +0.001 to +0.277)")


def test_a_defined_difference_keeps_its_interval():
    line = comparison_lines(_comparison(10.0))[0]
    assert "FM-prec +10 points (95 % CI -5 to +25)" in line


def test_a_difference_every_resample_repeats_is_not_given_a_zero_width_interval():
    """Both matchers' first matches missed the target in every episode: each resample's difference is 0, and
    "95 % CI +0 to +0" would claim a certainty a few episodes cannot give."""
    line = comparison_lines(_comparison(0.0, (0.0, 0.0)))[0]
    assert "FM-prec +0 points (the same in every resample: too few episodes to tell)" in line and "+0 to +0" not in line


def test_the_page_draws_the_look_alike_confusions_first():
    """Episodes where any matcher's first match was a look-alike come first, each group in id order; an episode a
    matcher never matched is drawn only where there is room."""
    lookalike = "same-category look-alike"  # as gallery.frame_roles names a frame's class
    verify = pd.Series({"e1": "target", "e3": lookalike, "e4": "other"})
    color = pd.Series({"e2": lookalike, "e3": "target"})
    assert shown_episodes(["e0", "e1", "e2", "e3", "e4"], [verify, color], 3) == ["e2", "e3", "e0"]
    assert shown_episodes(["e1", "e0"], [verify], 6) == ["e0", "e1"]


def test_the_page_counts_what_each_first_match_showed():
    """Per matcher, over every val episode: the roles its first matches showed, in the metrics' class order, and
    the episodes where it never fired."""
    lookalike = "same-category look-alike"
    verify = pd.DataFrame({"role": ["nothing", "target", "nothing"]}, index=["e1", "e2", "e3"])
    effnet = pd.DataFrame({"role": [lookalike, "nothing", "other", lookalike]}, index=["e0", "e1", "e2", "e3"])
    assert roles_line({"verify": verify, "effnet": effnet, "color": verify.iloc[:0]}, 4) == (
        "What each first match showed, over the 4 val episodes: verify: target 1, nothing 2, never fired 1; "
        f"effnet: {lookalike} 2, other 1, nothing 1; color: never fired 4.")


def test_a_stop_says_what_its_goal_point_landed_on():
    """The frame's class says what it shows; where the matcher pointed is another thing (a look-alike in the corner
    of a frame whose points are on the floor): the stop says both."""
    from types import SimpleNamespace

    walk = SimpleNamespace(outcome="other stop", fired_step=2.0, stop_step=2.0, d2g=6.0, landed_on="background")
    assert stop_line(walk) == ("the agent stops at step 2 (its goal point on: nothing annotated): other stop, "
                               "6.00 m from the target")
    assert "(its goal point on: a look-alike)" in stop_line(SimpleNamespace(**{**vars(walk), "landed_on":
                                                                                "same_category"}))
    never = SimpleNamespace(outcome="not found", fired_step=None, stop_step=None, d2g=0.8, landed_on=None)
    assert stop_line(never) == "the agent never stops: 0.8 m from the target at the walk's end"


def test_the_page_says_in_how_many_episodes_the_walk_shows_the_target():
    """Val walk frames only: e1 shows it at 2,500 px, e2 at 40 px, e3 never (a train episode and e3's walk-up view
    at 3,000 px do not count)."""
    labels = pd.DataFrame({"episode_id": ["e1", "e1", "e2", "e3", "e3", "t1"],
                           "split": ["val"] * 5 + ["train"], "approach": [False, False, False, False, True, False],
                           "target_pixels": [0, 2500, 40, 0, 3000, 9000]})
    labels["target_visible"] = labels.target_pixels > 0
    assert sight_line(labels) == ("The walks show the target in 2 of 3 val episodes, at 2,000 px or more in 1: where "
                                  "a walk never shows it, no matcher can find it.")


def _walks(*rows: dict) -> pd.DataFrame:
    """Episode rows with the columns the page reads (``navigation.EPISODE_COLUMNS``' that matter here)."""
    base = dict(fired_step=None, stop_step=None, d2g=4.0, landed_on=None, spl=0.0, steps=300, unplaced_candidates=0,
                rejected=0, rejections=None, rejected_target=0, rejected_lookalike=0, rejected_other=0,
                rejected_nothing=0)
    return pd.DataFrame([base | row for row in rows]).set_index("episode_id", drop=False)


def test_the_closed_loop_says_what_it_turned_down_and_where_it_stopped():
    """Hand-made walks: the closed loop turned a look-alike down and then found the target, where the first match
    had stopped at the look-alike."""
    loop = _walks(dict(episode_id="e1", outcome="success", fired_step=51, stop_step=187, d2g=0.5, landed_on="target",
                       spl=0.6, rejected=1, rejections="51:same_category:0.412", rejected_lookalike=1),
                  dict(episode_id="e2", outcome="not found"))
    first = _walks(dict(episode_id="e1", outcome="category error", fired_step=51, stop_step=51),
                   dict(episode_id="e2", outcome="not found"))
    line = closed_loop_line({"verify": loop}, {"verify": first})
    assert "approach:1" in line and line.endswith("verify SR 50.0 %, CE 0.0 % (the stop rule above: SR 0.0 %, CE "
                                                  "50.0 %), candidates turned down: 1 (look-alikes 1, the target 0).")
    assert closed_loop_caption(loop.loc["e1"]) == (
        "closed loop: turned down a look-alike at step 51 (close look 0.412); the agent stops at step 187 (its goal "
        "point on: the target): success, 0.50 m from the target")
    assert closed_loop_caption(loop.loc["e2"]).startswith("closed loop: turned down nothing; the agent never stops")
    assert closed_loop_line({"verify": pd.DataFrame()}, {"verify": first}) is None  # no house to walk up in
