"""How far one sigma carries: chosen on the other sets, read on one, beside that set's own best sigma."""

from __future__ import annotations

import numpy as np
import pytest

from pin_match.cli import main
from pin_match.evaluation.core.intervals import instance_clusters
from pin_match.evaluation.core.labels import frame_labels
from pin_match.evaluation.core.metrics import Bootstrap
from pin_match.evaluation.flows.carry import (
    CarryError,
    ScoredSet,
    carried,
    carry_risk,
    chosen_and_carried,
    headline,
    leave_one_out,
    pooled,
)

BOOT = Bootstrap(n_boot=50)
# per episode of the tiny set: step 0 the target, 1 a same-category look-alike, 2 another object, 3 nothing
LOW = (0.8, 0.6, 0.2, 0.1)    # a house whose look-alikes score low
HIGH = (0.95, 0.85, 0.2, 0.1)  # one whose look-alike scores above the first house's target


def scored_set(fs, scores) -> ScoredSet:
    frames = frame_labels(fs).assign(score=lambda t: [scores[s] for s in t.step])
    return ScoredSet(tuning=frames, reading=frames, clusters=instance_clusters(fs.episodes))


def test_a_sigma_chosen_where_look_alikes_score_low_matches_them_where_they_score_high(tiny_frameset):
    low, high = scored_set(tiny_frameset, LOW), scored_set(tiny_frameset, HIGH)
    rows = leave_one_out({"low": low, "high": high}, BOOT).set_index("set")
    on_high = rows.loc["high"]  # sigma chosen on the low house: between its look-alike and its target
    assert 0.6 < on_high.sigma <= 0.8 and 0.85 < on_high.own_sigma <= 0.95
    assert on_high.cm == 50.0 and on_high.own_cm == 0.0  # carried: every look-alike frame matched beside the target
    assert on_high.tm == 50.0  # TM and CM: shares of the matched frames
    on_low = rows.loc["low"]  # sigma chosen on the high house: above the low house's target, nothing matched
    assert on_low.sigma > 0.8 and on_low.match == 0.0 and on_low.own_cm == 0.0
    # no CM there, but no episode finds its target either: the success gap says so
    assert (on_low.first_success, on_low.own_first_success, on_low.success_gap) == (0.0, 100.0, 100.0)
    assert on_low.own_match == 100.0
    assert list(rows.index) == ["high", "low"] or np.isnan(on_low.cm)  # worst (highest CM) first


def test_read_at_its_own_best_sigma_a_set_loses_nothing(tiny_frameset):
    frames = scored_set(tiny_frameset, HIGH)
    row = carried(frames.reading, 0.9, frames.clusters, BOOT)
    assert row["own_sigma"] == pytest.approx(row["sigma"], abs=0.05) and row["first_gap"] == 0.0
    assert row["cm"] == row["own_cm"] == 0.0 and row["auroc_same"] == 1.0 and row["success_gap"] == 0.0


def test_pooled_sets_keep_their_frames_apart(tiny_frameset):
    a = scored_set(tiny_frameset, LOW).tuning
    both = pooled([a, a])
    assert len(both) == 2 * len(a) and both.frame_id.is_unique
    assert both.episode_id.nunique() == 2 * a.episode_id.nunique()


def test_leaving_one_out_needs_two_sets(tiny_frameset):
    with pytest.raises(CarryError, match="at least two"):
        leave_one_out({"only": scored_set(tiny_frameset, LOW)}, BOOT)


def test_carry_command_scores_each_set_and_prints_the_rows(tiny_frameset, tmp_path, capsys):
    import shutil

    twin = tmp_path / "twin"
    shutil.copytree(tiny_frameset.root, twin)
    code = main(["carry", str(tiny_frameset.root), f"{twin}:val", "--matcher", "color", "--cache",
                 str(tmp_path / "scores"), "--bootstrap", "20", "--json", str(tmp_path / "carry.json"), "--quiet"])
    out = capsys.readouterr().out
    assert code in (0, None) and "sigma chosen on every other set" in out and f"{twin}:val" in out
    assert (tmp_path / "carry.json").exists()


def test_a_variant_is_chosen_without_the_set_it_is_read_on(tiny_frameset):
    """Variant A: houses 1, 2 low, 3 high; B: 1 high, 2 and 3 low. Left out, each set gets the variant that carried
    on the other two: 3 gets A (1 and 2 agree under A), 1 gets B; for 2 both fail on the others (a sigma from a
    high house matches nothing in a low one) and the first listed, A, is kept."""
    low, high = scored_set(tiny_frameset, LOW), scored_set(tiny_frameset, HIGH)
    variants = {"A": {"h1": low, "h2": low, "h3": high}, "B": {"h1": high, "h2": low, "h3": low}}
    assert carry_risk({"h1": low, "h2": low}) == (0.0, 0.0, 0.0)
    assert carry_risk({"h1": low, "h3": high}) == (np.inf, np.inf, 100.0)  # high -> low: nothing matched
    rows = chosen_and_carried(variants, BOOT).set_index("set")
    assert rows.variant.to_dict() == {"h1": "B", "h2": "A", "h3": "A"}
    assert rows.loc["h3", "cm"] == 50.0 and rows.loc["h1", "cm"] == 50.0  # the choice never saw the set it is read on
    assert rows.loc["h2", "chosen_by_cm"] == np.inf
    top = headline(rows.reset_index())
    assert top["worst_cm"] == 50.0 and top["worst_cm_set"] in ("h1", "h3")
    # every house shows its target first, so wherever a carried sigma matches, the first match is the target
    assert top["largest_success_gap"] == 0.0 and top["lowest_match"] == 100.0
    with pytest.raises(CarryError, match="at least three"):
        chosen_and_carried({"A": {"h1": low, "h2": low}, "B": {"h1": low, "h2": low}}, BOOT)
    with pytest.raises(CarryError, match="same frame-sets"):
        chosen_and_carried({"A": {"h1": low, "h2": low, "h3": low}, "B": {"h1": low, "h2": low, "h4": low}}, BOOT)


def carry_args(tiny_frameset, tmp_path) -> list[str]:
    """``pin-match carry`` of ``color`` on three copies of the tiny set (one left out at a time)."""
    import shutil

    sets = [str(tiny_frameset.root)]
    for name in ("b", "c"):
        shutil.copytree(tiny_frameset.root, tmp_path / name)
        sets.append(str(tmp_path / name))
    return ["carry", *sets, "--matcher", "color", "--cache", str(tmp_path / "scores"), "--bootstrap", "20", "--quiet"]


def test_carry_command_varies_one_config_key_in_one_pass(tiny_frameset, tmp_path, capsys):
    import json

    args = carry_args(tiny_frameset, tmp_path)
    code = main([*args, "--vary", "stride=4,8", "--json", str(tmp_path / "carry.json")])
    out = capsys.readouterr().out
    assert code in (0, None) and "(stride=4)" in out and "(stride=8)" in out
    assert "stride chosen on the other sets" in out
    report = json.loads((tmp_path / "carry.json").read_text())
    assert list(report["rows"]) == ["stride=4", "stride=8"] and len(report["chosen"]["rows"]) == 3
    assert {r["variant"] for r in report["chosen"]["rows"]} <= {"stride=4", "stride=8"}
    assert len(list((tmp_path / "scores").glob("color@*/*/scores_all.parquet"))) == 2  # a table per variant (the
    # copies have the set's fingerprint: one table serves all three)
    assert main([*args, "--vary", "stride=4"]) == 2
    assert "at least two different values" in capsys.readouterr().err


def shifted_house(fs, shift: float, val_shift: float | None = None) -> ScoredSet:
    """The tiny set read as a walk that sees the other object and nothing first, then the look-alike, then the target
    (steps reordered), every score raised by ``shift`` (the val episode's by ``val_shift`` where given): a house
    whose level differs."""
    order = {2: 0, 3: 1, 1: 2, 0: 3}  # tiny step -> walk step
    scores = {0: 0.6, 1: 0.35, 2: 0.2, 3: 0.25}  # by tiny step: target 0.6, look-alike 0.35, other 0.2, nothing 0.25
    shifts = {"ep_train": shift, "ep_val": shift if val_shift is None else val_shift}
    frames = frame_labels(fs).assign(score=lambda t: [scores[s] + shifts[e] for s, e in zip(t.step, t.episode_id)],
                                     step=lambda t: [order[s] for s in t.step])
    return ScoredSet(tuning=frames, reading=frames, clusters=instance_clusters(fs.episodes))


def test_a_house_relative_line_carries_a_level_shift_upward_but_sigma_stays_absolute(tiny_frameset):
    from pin_match.evaluation.core.stop import HouseStop

    sets = {"low": shifted_house(tiny_frameset, 0.0), "high": shifted_house(tiny_frameset, 0.3)}
    plain = leave_one_out(sets, BOOT).set_index("set")
    # PIN's rule: sigma from the low house (0.6, its target's score) fires in the high house on its look-alike (0.65)
    # before its target; from the high house (0.9) nothing fires in the low one
    assert plain.loc["high", "first_precision"] == 0.0 and plain.loc["high", "cm"] == 50.0
    assert plain.loc["low", "match"] == 0.0 and plain.loc["low", "success_gap"] == 100.0
    house = leave_one_out(sets, BOOT, HouseStop(top=1, margin=0.2)).set_index("set")
    # the look-alike clears the house by 0.1 (0.65 over 0.55), the target by 0.25: in the high house the line keeps
    # the look-alike out and the target fires, at the low house's sigma (0.6)
    assert house.loc["high", "sigma"] == pytest.approx(0.6) and house.loc["high", "first_precision"] == 100.0
    assert house.loc["high", "cm"] == 0.0 and house.loc["high", "first_gap"] == 0.0
    # sigma is still an absolute floor, chosen at the top of its ties on the high house (its target, 0.9): above the
    # low house's target, so nothing fires there
    assert house.loc["low", "sigma"] == pytest.approx(0.9) and house.loc["low", "match"] == 0.0
    assert np.isnan(house.sr).all()  # no geometry: no navigation estimate


def test_the_policy_is_chosen_without_the_set_it_is_read_on(tiny_frameset):
    """Every house holds a low episode and one 0.3 higher: no sigma serves both under PIN's rule (the low target, 0.6,
    is below the high look-alike, 0.65); it is chosen at the high target (0.9), matching nothing in the low episodes:
    no CM and no precision gap, half the episodes lost, as at each set's own best sigma. The house line serves both
    at sigma 0.6 (success 50 points above PIN's own best); the success gap breaks the tie, so the house policy is
    chosen without each set and stops on the target everywhere."""
    from pin_match.evaluation.core.stop import FIRST_MATCH, HouseStop

    shifts = ((0.0, 0.3), (0.3, 0.0), (0.0, 0.3))
    sets = {f"h{i}": shifted_house(tiny_frameset, low, high) for i, (low, high) in enumerate(shifts)}
    house = HouseStop(top=1, margin=0.2)
    assert carry_risk(sets, FIRST_MATCH) == (0.0, 0.0, 0.0) and carry_risk(sets, house) == (0.0, 0.0, -50.0)
    rows = chosen_and_carried({"pin": sets, "house": sets}, BOOT, {"pin": FIRST_MATCH, "house": house})
    assert (rows.variant == "house").all() and (rows.first_precision == 100.0).all() and (rows.cm == 0.0).all()
    assert (rows.sigma == 0.6).all()


def test_carry_command_compares_stop_policies(tiny_frameset, tmp_path, capsys):
    import json

    args = carry_args(tiny_frameset, tmp_path)
    code = main([*args, "--policy", "1-of-1,2-of-3", "--policy=house:top1+0.1", "--json", str(tmp_path / "c.json")])
    out = capsys.readouterr().out
    assert code in (0, None) and "(house:top1+0.1)" in out and "(2-of-3)" in out
    assert "stop policy chosen on the other sets alone" in out
    report = json.loads((tmp_path / "c.json").read_text())
    assert report["policies"] == {"1-of-1": "1-of-1", "2-of-3": "2-of-3", "house:top1+0.1": "house:top1+0.1"}
    assert {r["variant"] for r in report["chosen"]["rows"]} <= set(report["policies"])
    assert main([*args, "--policy", "house:top1+0.1,house:top1+0.10"]) == 2
    assert "named twice" in capsys.readouterr().err
    assert main([*args, "--policy", "house:best"]) == 2
    assert "house:topT+MARGIN" in capsys.readouterr().err


def test_a_carried_row_says_what_a_look_further_policy_commits_to(tiny_frameset):
    """Per episode of the tiny set: the target at step 0, a look-alike at step 1. Where the look-alike outscores the
    target, PIN's rule still commits to the target (it fires first) and a window of one more frame commits to the
    look-alike: the commit columns follow the decisions, as shares of every episode."""
    from pin_match.evaluation.core.stop import LookFurther

    frames = scored_set(tiny_frameset, (0.7, 0.9, 0.2, 0.1))
    pin = carried(frames.reading, 0.6, frames.clusters, BOOT)
    assert (pin["commit_target"], pin["commit_lookalike"], pin["looked"]) == (100.0, 0.0, 1.0)
    look = carried(frames.reading, 0.6, frames.clusters, BOOT, LookFurther(window=1))
    assert (look["commit_target"], look["commit_lookalike"], look["looked"]) == (0.0, 100.0, 2.0)
    assert look["own_commit_target"] == 0.0 and look["commit_gap"] == 0.0  # no sigma saves it from the look-alike
    assert look["first_success"] == 0.0 and look["cm"] == 100.0  # the found frame is the one it commits to
