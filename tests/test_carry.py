"""How far one sigma carries: chosen on the other sets, read on one, beside that set's own best sigma."""

from __future__ import annotations

import numpy as np
import pytest

from pin_match.cli import main
from pin_match.evaluation.carry import (
    CarryError,
    ScoredSet,
    carried,
    carry_risk,
    chosen_and_carried,
    headline,
    leave_one_out,
    pooled,
)
from pin_match.evaluation.intervals import instance_clusters
from pin_match.evaluation.labels import frame_labels
from pin_match.evaluation.metrics import Bootstrap

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
    assert carry_risk({"h1": low, "h2": low}) == (0.0, 0.0)
    assert carry_risk({"h1": low, "h3": high}) == (np.inf, np.inf)  # high -> low: nothing matched
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


def test_carry_command_varies_one_config_key_in_one_pass(tiny_frameset, tmp_path, capsys):
    import json
    import shutil

    sets = [str(tiny_frameset.root)]
    for name in ("b", "c"):
        shutil.copytree(tiny_frameset.root, tmp_path / name)
        sets.append(str(tmp_path / name))
    args = ["carry", *sets, "--matcher", "color", "--cache", str(tmp_path / "scores"), "--bootstrap", "20", "--quiet"]
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
