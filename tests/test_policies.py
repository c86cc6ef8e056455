"""Stop policies: 1-of-1 is today's rule exactly; 2-of-3 by hand; the sweep of any policy; tuning sigma for one."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pin_match.evaluation.core.commits import policy_metrics
from pin_match.evaluation.core.metrics import COUNT_KEYS, METRIC_KEYS, frame_arrays, threshold_metrics
from pin_match.evaluation.core.policies import policy_sigma, policy_sweep, tune_policy
from pin_match.evaluation.core.stop import FIRST_MATCH, HouseStop, PolicyError, StopPolicy, found_frames
from pin_match.evaluation.core.tuning import sigma_for


def scored_episodes(roles: dict[str, str], scores: dict[str, list[float]]) -> pd.DataFrame:
    """Frames from per-episode role strings (T target, C look-alike, G other, O nothing) and scores."""
    rows = []
    for episode, codes in roles.items():
        for step, (code, score) in enumerate(zip(codes, scores[episode])):
            rows.append(dict(frame_id=f"{episode}_{step}", episode_id=episode, step=step, target_category="mug",
                             target_visible=code == "T", same_visible=code == "C", other_visible=code == "G",
                             target_seen=float(code == "T"), score=score))
    return pd.DataFrame(rows)


def random_scored(seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    roles = {f"e{e}": "".join(rng.choice(list("TCGO"), 10)) for e in range(8)}
    return scored_episodes(roles, {e: list(np.round(rng.uniform(size=10), 2)) for e in roles})


@pytest.mark.parametrize("seed", range(5))
def test_one_of_one_is_todays_rule_exactly(seed):
    scored = random_scored(seed)
    for sigma in (0.0, 0.3, 0.5, 0.77, 1.1):
        today = threshold_metrics(frame_arrays(scored), sigma)
        got = policy_metrics(scored, sigma, StopPolicy(1, 1))
        for key in (*COUNT_KEYS, *METRIC_KEYS):
            assert got[key] == today[key] or (math.isnan(got[key]) and math.isnan(today[key])), key


def test_two_of_three_by_hand():
    # e1: steps 0..5 matched at 0.5:   1 0 1 1 0 0 -> windows of 3 hold 1 1 2 2 2 1 matches: fires at 2, 3, 4
    # e2: matched 1 1 0 0 0 0 -> windows hold 1 2 2 1 0 0: fires at 1, 2; no window reaches back into e1
    scored = scored_episodes({"e1": "CCTTOO", "e2": "TCOOOO"},
                             {"e1": [0.9, 0.1, 0.8, 0.7, 0.2, 0.1], "e2": [0.6, 0.9, 0.1, 0.1, 0.1, 0.1]})
    arr = frame_arrays(scored)
    found = found_frames(arr, 0.5, StopPolicy(2, 3))
    assert found.astype(int).tolist() == [0, 0, 1, 1, 1, 0] + [0, 1, 1, 0, 0, 0]
    m = policy_metrics(scored, 0.5, StopPolicy(2, 3))
    assert m["n_matched"] == 5 and m["n_tm"] == 2 and m["n_cm"] == 1 and m["n_om"] == 2
    assert m["tm_pct"] == 40.0 and m["cm_pct"] == 20.0
    assert m["first_match_precision"] == 50.0  # e1 first fires on the target, e2 on the look-alike
    assert m["frames_to_first_match"] == 2.5  # e1: 3rd frame, e2: 2nd frame
    assert policy_metrics(scored, 0.5)["frames_to_first_match"] == 1.0  # 1-of-1 stops at both first frames


def test_policy_text_and_bad_policies():
    assert StopPolicy.parse("2-of-3") == StopPolicy(2, 3) and str(StopPolicy(2, 3)) == "2-of-3"
    for bad in ("3-of-2", "0-of-1"):
        with pytest.raises(PolicyError, match="1 <= k <= n"):
            StopPolicy.parse(bad)
    with pytest.raises(PolicyError, match="K-of-N"):
        StopPolicy.parse("two of three")


def test_tune_for_a_policy(tiny_frameset):
    from test_report_page import make_table

    table = make_table(tiny_frameset)
    result = tune_policy(table, tiny_frameset, StopPolicy(1, 1), objective="first-match", split="train")
    # train episode: target 0.9 then 0.2, 0.1, 0.1: only a sigma above 0.2 stops first at the target
    assert result["sigma"] == 0.9 and result["objective_value"] == 100.0 and result["policy"] == "1-of-1"
    two = tune_policy(table, tiny_frameset, StopPolicy(2, 2), objective="first-match", split="train")
    # 2-of-2 first fires on step 1 (a look-alike) at best: undefined success is never chosen over 0
    assert two["metrics_at_sigma"]["first_match_precision"] in (0.0, None)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("policy", [StopPolicy(1, 1), HouseStop(top=1, margin=0.1), HouseStop(top=3, margin=-0.05),
                                    StopPolicy(2, 3)])
def test_the_sweep_of_a_policy_is_its_metrics_at_every_distinct_score(seed, policy):
    """A 1-of-1 window is swept once on the gated scores: the same counts as applying each sigma in turn."""
    scored = random_scored(seed)
    curve = policy_sweep(scored, policy)
    assert curve["sigma"].tolist() == sorted(set(scored["score"]))
    for _, row in curve.iterrows():
        each = policy_metrics(scored, row["sigma"], policy)
        for key in (*COUNT_KEYS, *METRIC_KEYS):
            assert row[key] == each[key] or (math.isnan(row[key]) and math.isnan(each[key])), (row["sigma"], key)


def test_pin_s_rule_chooses_the_sigma_of_the_plain_sweep():
    for seed in range(4):
        scored = random_scored(seed)
        assert policy_sigma(scored, FIRST_MATCH) == sigma_for(scored)


def test_tune_for_a_house_relative_policy(tiny_frameset):
    from test_report_page import make_table

    table = make_table(tiny_frameset)
    result = tune_policy(table, tiny_frameset, StopPolicy.parse("house:top1+0.1"), split="train")
    # the train episode shows the target first (0.9): no earlier frame, so sigma alone decides there
    assert result["policy"] == "house:top1+0.1" and result["objective_value"] == 100.0
    assert result["metrics_at_sigma"]["frames_to_first_match"] == 1.0


def test_tune_command_takes_a_house_relative_policy(tiny_frameset, tmp_path, capsys):
    import json

    from test_report_page import make_table

    from pin_match.cli import main

    make_table(tiny_frameset).write(tmp_path / "scores.parquet")
    out = tmp_path / "t.json"
    args = ["tune", str(tmp_path / "scores.parquet"), "--frameset", str(tiny_frameset.root), "--out", str(out)]
    assert main([*args, "--policy", "house:top1+0.1"]) in (0, None)
    assert "stop policy house:top1+0.1" in capsys.readouterr().out
    assert json.loads(out.read_text())["policy"] == "house:top1+0.1"
    assert main([*args, "--policy", "house:top+0.1"]) == 2
    assert "house:topT+MARGIN" in capsys.readouterr().err
