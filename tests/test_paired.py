"""The paired bootstrap and McNemar's test on constructed pairs of matchers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pin_match.evaluation import EvalContext
from pin_match.evaluation.core.intervals import weighted_auroc
from pin_match.evaluation.core.metrics import Bootstrap, auroc, detection_metrics, frame_arrays
from pin_match.evaluation.core.paired import (
    PairedError,
    disagreements,
    first_match_outcomes,
    mcnemar,
    paired_comparison,
)


def constructed(n_episodes: int = 12, seed: int = 0) -> pd.DataFrame:
    """Episodes of 6 frames: a look-alike at steps 0-1, the target at 2-3, nothing at 4-5; random scores."""
    rng = np.random.default_rng(seed)
    rows = []
    for e in range(n_episodes):
        for step in range(6):
            rows.append(dict(frame_id=f"e{e:02d}_{step}", episode_id=f"e{e:02d}", step=step,
                             target_category="mug", target_visible=step in (2, 3), same_visible=step in (0, 1),
                             other_visible=False, target_seen=float(step in (2, 3)), score=rng.uniform(0.2, 0.8)))
    return pd.DataFrame(rows)


def test_identical_matchers_differ_by_zero_with_an_interval_around_it():
    a = constructed()
    table = paired_comparison(a, a.copy(), 0.5, 0.5, boot=Bootstrap(n_boot=200))
    assert (table["B - A"] == 0).all()
    assert ((table["CI low"] <= 0) & (table["CI high"] >= 0)).all()
    np.testing.assert_allclose(table.loc["AUROC", "A"], detection_metrics(frame_arrays(a), 0.5)["auroc_target"])


def test_better_on_every_episode_gives_an_interval_above_zero():
    a = constructed()
    b = a.copy()
    b.loc[b.target_visible, "score"] += 1.0  # B ranks the target first and matches nothing else
    b.loc[~b.target_visible, "score"] -= 0.5
    table = paired_comparison(a, b, 0.5, 0.5, boot=Bootstrap(n_boot=200))
    for metric in ("AUROC", "AUROC-same", "TM", "FM-prec"):
        assert table.loc[metric, "CI low"] > 0, metric
    assert table.loc["FM-prec", "B"] == 100.0


def test_episodes_of_one_instance_are_resampled_together():
    a = constructed(n_episodes=12)
    b = a.copy()
    b.loc[b.target_visible, "score"] += 1.0
    # B is better in only one of 12 episodes ...
    b.loc[b.episode_id != "e00", "score"] = a.loc[a.episode_id != "e00", "score"]
    episodes = sorted(set(a.episode_id))
    one_each = {e: e for e in episodes}
    # ... which the grouping puts alone, or with all 11 others into one instance: then only 2 units are drawn
    two_units = {e: ("x" if e == "e00" else "y") for e in episodes}
    narrow = paired_comparison(a, b, 0.5, 0.5, clusters=one_each, boot=Bootstrap(n_boot=400))
    grouped = paired_comparison(a, b, 0.5, 0.5, clusters=two_units, boot=Bootstrap(n_boot=400))
    assert narrow.attrs["n_units"] == 12 and grouped.attrs["n_units"] == 2
    # with two units, a quarter of resamples never draw e00: the interval of TM reaches exactly 0
    assert grouped.loc["TM", "CI low"] == 0.0 < narrow.loc["TM", "CI high"]
    width = (grouped["CI high"] - grouped["CI low"]).loc["TM"]
    assert width > (narrow["CI high"] - narrow["CI low"]).loc["TM"]


def test_weighted_auroc_equals_auroc_with_repeated_frames():
    rng = np.random.default_rng(1)
    score = np.round(rng.uniform(size=40), 1)  # ties
    positive = rng.uniform(size=40) < 0.4
    weights = rng.integers(0, 3, size=40).astype(float)
    _, inverse = np.unique(score, return_inverse=True)
    got = weighted_auroc(inverse, inverse.max() + 1, positive.astype(float), (~positive).astype(float), weights)
    repeated = np.repeat(np.arange(40), weights.astype(int))
    assert got == pytest.approx(auroc(score[repeated][positive[repeated]], score[repeated][~positive[repeated]]))


def test_mcnemar_by_hand():
    a = np.array([1, 1, 1, 1, 1, 0, 0, 1], bool)
    b = np.array([0, 0, 0, 0, 0, 0, 1, 1], bool)
    result = mcnemar(a, b)
    assert (result["only_a"], result["only_b"], result["both"], result["neither"]) == (5, 1, 1, 1)
    assert result["p_value"] == pytest.approx(2 * (1 + 6) / 64)  # 2 * P(X <= 1), X ~ Bin(6, 1/2)
    assert mcnemar(a, a)["p_value"] == 1.0


def test_first_match_outcomes_and_disagreements():
    a = constructed(n_episodes=3)
    b = a.copy()
    b.loc[b.target_visible, "score"] += 1.0
    b.loc[~b.target_visible, "score"] = 0.0
    first_a, first_b = first_match_outcomes(a, b, 0.5, 0.5)
    assert first_b.all() and len(first_a) == 3
    gap = disagreements(a, b, 0.5, 0.5, cap=100)
    assert len(gap) == int(((a.score >= 0.5) != (b.score >= 0.5)).sum())
    assert gap.rank_gap.is_monotonic_decreasing


def test_different_frames_are_refused():
    a = constructed()
    with pytest.raises(PairedError, match="B scored 0 frames|A scored 6 frames"):
        paired_comparison(a, a[a.episode_id != "e00"], 0.5, 0.5, boot=Bootstrap(n_boot=10))


def test_compare_writes_the_folder(tiny_frameset, tmp_path):
    from test_report_page import make_table

    from pin_match.evaluation.core.sigma import SigmaChoice
    from pin_match.evaluation.flows.compare import AtSigma, compare
    from pin_match.scoring.table import ScoreTable

    a = make_table(tiny_frameset)
    frames = a.frames.copy()
    frames["score"] = np.where(frames.step == 0, 0.9, 0.1)  # B: the target and nothing else
    b = ScoreTable(frames, {**a.meta, "matcher_id": "better@def"})
    sigma = SigmaChoice(0.5, "given", "test")
    done = compare(AtSigma(a, sigma), AtSigma(b, sigma), EvalContext(tiny_frameset, Bootstrap(n_boot=50)), tmp_path,
                   split="all")
    paired, test = done.paired, done.test
    assert paired.loc["FM-prec", "better@def"] == 100.0 and paired.loc["FM-prec", "stub@abc"] == 50.0
    assert (test["only_a"], test["only_b"], test["both"]) == (0, 1, 1)
    assert all(p.is_file() and p.parent == tmp_path for p in (done.folder.csv, done.folder.markdown, done.folder.page))
    page = done.folder.page.read_text(encoding="utf-8")
    assert "ep_val_0002" in page and "McNemar" in page  # the planted false alarm of A is a disagreement
