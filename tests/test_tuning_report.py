"""Tuning and reports end to end on the tiny frame-set with a hand-made score table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pin_match.evaluation import Bootstrap, EvalContext, EvaluationError
from pin_match.evaluation.core.labels import LabelError, frame_labels, localisation_hits, scored_frames
from pin_match.evaluation.core.sigma import PAPER_THRESHOLDS, SigmaError, load_threshold, resolve_sigma
from pin_match.evaluation.core.tables import Row, latex_table, markdown_table, report_row, side_by_side, tuning_row
from pin_match.evaluation.core.tuning import OBJECTIVES, TuningError, tune, write_thresholds
from pin_match.evaluation.flows.report import report
from pin_match.scoring.table import ScoreTable

ON_TARGET = (148.0, 348.0)  # centre of the disc painted at (100, 300) with radius ~38 px
OFF_TARGET = (10.0, 10.0)

# per episode, steps 0..3 show: target, same-category distractor, other distractor, nothing
SCORES = {"ep_train": [0.8, 0.85, 0.2, 0.1], "ep_val": [0.9, 0.7, 0.3, 0.1]}


def make_table(fs, tmp_path) -> ScoreTable:
    rows = []
    for episode, scores in SCORES.items():
        for step, score in enumerate(scores):
            points, point_scores = [ON_TARGET], [score]
            if episode == "ep_val" and step == 0:  # one point on the target, one off it at a lower score
                points, point_scores = [ON_TARGET, OFF_TARGET], [0.9, 0.6]
            rows.append(dict(frame_id=f"{episode}_{step:04d}", episode_id=episode, step=step,
                             split=episode.split("_")[1], score=score, crop_scores=[score, score],
                             points_x=[p[0] for p in points], points_y=[p[1] for p in points],
                             point_scores=point_scores, view=-1))
    meta = dict(matcher="stub", matcher_id="stub@abc", config_hash="abc", frameset_fingerprint=fs.fingerprint,
                default_sigma=0.5, modality="visual")
    ScoreTable(pd.DataFrame(rows), meta).write(tmp_path / "scores.parquet")
    return ScoreTable.read(tmp_path / "scores.parquet")


def test_labels_of_the_tiny_frameset(tiny_frameset):
    labels = frame_labels(tiny_frameset).set_index("frame_id")
    assert list(labels.loc[[f"ep_val_{s:04d}" for s in range(4)], "target_visible"]) == [True, False, False, False]
    assert list(labels.loc[[f"ep_val_{s:04d}" for s in range(4)], "same_visible"]) == [False, True, False, False]
    assert list(labels.loc[[f"ep_val_{s:04d}" for s in range(4)], "other_visible"]) == [False, False, True, False]
    row = labels.loc["ep_val_0000"]
    assert row.target_category == "mug" and row.target_depth == pytest.approx(1.5)
    # the disc covers ~4,600 of 230,400 pixels, under PIN's 5 %: not "seen"
    assert 4000 < row.target_pixels < 5000 and row.target_seen == 0.0


def test_scores_from_another_frameset_are_rejected(tiny_frameset, tmp_path):
    table = make_table(tiny_frameset, tmp_path)
    table.frames.loc[0, "frame_id"] = "elsewhere_0000"
    with pytest.raises(LabelError, match="elsewhere_0000"):
        scored_frames(frame_labels(tiny_frameset), table)


def test_localisation_hits(tiny_frameset, tmp_path):
    hits = localisation_hits(tiny_frameset, make_table(tiny_frameset, tmp_path), 0.5)
    # matched target frames: ep_train_0000 (one point, on) and ep_val_0000 (two points, one on)
    assert hits.set_index("frame_id").to_dict("index") == {
        "ep_train_0000": dict(n_points=1, n_on_target=1, hit=True),
        "ep_val_0000": dict(n_points=2, n_on_target=1, hit=True)}


@pytest.mark.parametrize("objective", sorted(k for k, o in OBJECTIVES.items() if not o.navigation))
def test_tune_on_train(tiny_frameset, tmp_path, objective):
    table = make_table(tiny_frameset, tmp_path)
    result = tune(table, tiny_frameset, objective=objective)
    # train scores: target .8, same .85, other .2, nothing .1. At .85 only the distractor matches (first match
    # wrong, TM 0 %); at .8 the target is matched and first: every objective peaks there (first-match: 100 %
    # also at .2 and .1, so the tie goes to the highest sigma)
    assert result["sigma"] == 0.8
    assert result["split"] == "train" and result["frameset_fingerprint"] == tiny_frameset.fingerprint
    assert result["metrics_at_sigma"]["tm_pct"] == 50.0 and result["n_candidates"] == 4
    path = write_thresholds(result, tmp_path / "thresholds" / "stub.json")
    assert load_threshold(path, "stub").value == 0.8 and load_threshold(path, "stub@abc").value == 0.8
    assert load_threshold(path, "stub").source == f"tuned: {objective} on train"
    assert tuning_row(result).sigma_source == f"tuned: {objective} on train"
    with pytest.raises(SigmaError, match="not 'dino'"):
        load_threshold(path, "dino")


def test_tune_errors(tiny_frameset, tmp_path):
    table = make_table(tiny_frameset, tmp_path)
    with pytest.raises(TuningError, match="unknown objective"):
        tune(table, tiny_frameset, objective="accuracy")
    with pytest.raises(TuningError, match="keeps %Match >= 101"):
        tune(table, tiny_frameset, objective="tm-at-match", match_floor=101)
    table.meta["frameset_fingerprint"] = "0000"  # the one fingerprint check, in tune too
    with pytest.raises(EvaluationError, match="computed on frame-set 0000"):
        tune(table, tiny_frameset)


def test_no_train_split_says_the_way_out(tiny_frameset, tmp_path):
    """Issue 14.4: one message naming the three ways on."""
    val_only = make_table(tiny_frameset, tmp_path).split("val")
    with pytest.raises(EvaluationError) as err:
        tune(val_only, tiny_frameset)
    msg = str(err.value)
    assert "no frames of split 'train' (it has ['val'])" in msg
    assert "--split val" in msg and "--threshold SIGMA" in msg and "--thresholds paper" in msg


def test_load_paper_thresholds(tmp_path):
    path = tmp_path / "paper.json"
    path.write_text(json.dumps({"source": "PIN", "thresholds": {"dinov2": {"sigma": 0.5}, "ieve": {"sigma": None}}}))
    assert load_threshold(path, "dinov2").value == 0.5
    assert load_threshold(path, "dinov2@123").value == 0.5
    with pytest.raises(SigmaError, match="gives no sigma for 'ieve'.*gives one for dinov2"):
        load_threshold(path, "ieve")
    with pytest.raises(SigmaError, match="no threshold for 'owl'; it covers only dinov2"):
        load_threshold(path, "owl")
    path.write_text(json.dumps({"thresholds": {"dinov2": {"sigma": "high"}}}))
    with pytest.raises(SigmaError, match="not a number"):
        load_threshold(path, "dinov2")


def test_paper_thresholds_name_what_they_cover():
    """Issue 14.5: sift is not in the paper; the message lists the matchers that are."""
    choice = load_threshold("paper", "dinov2@abc")
    assert (choice.value, choice.source) == (0.5, "paper")
    with pytest.raises(SigmaError) as err:
        load_threshold("paper", "sift@123")
    covered = sorted(k for k, v in json.loads(PAPER_THRESHOLDS.read_text())["thresholds"].items()
                     if v["sigma"] is not None)
    assert f"no threshold for 'sift@123'; it covers only {', '.join(covered)}" in str(err.value)
    assert "superglue" in covered and "color" not in covered


def test_missing_thresholds_file_says_how_to_make_one(tmp_path):
    with pytest.raises(SigmaError, match="run `pin-match tune` first.*--threshold SIGMA, or --thresholds paper"):
        load_threshold(tmp_path / "thresholds" / "sift.json", "sift")
    assert resolve_sigma("sift@1", 8.0).source == "matcher default"
    with pytest.raises(SigmaError, match="not a finite number"):
        resolve_sigma("sift@1", 8.0, sigma=float("nan"))


def test_report_end_to_end(tiny_frameset, tmp_path):
    table = make_table(tiny_frameset, tmp_path)
    out = tmp_path / "report"
    # sigma: the table's default 0.5; split val
    result = report(table, EvalContext(tiny_frameset, Bootstrap(n_boot=50)), out)
    for name in ("metrics.json", "per_category.csv", "metrics.md", "metrics.tex", "sigma_curves.png",
                 "score_distributions.png", "per_category.png"):
        assert (out / name).stat().st_size > 0, name
    saved = json.loads((out / "metrics.json").read_text())
    m = saved["metrics"]
    assert saved["sigma"] == 0.5 and saved["sigma_source"] == "matcher default" and saved["split"] == "val"
    assert saved["sigma_detail"] == "stub's default sigma"
    # val at .5: target (.9) and same-category (.7) frames matched; the first one (step 0) is the target
    assert (m["tm_pct"], m["cm_pct"], m["nm_pct"], m["gm_pct"], m["om_pct"]) == (50.0, 50.0, 0.0, 0.0, 0.0)
    assert m["match_pct"] == 100.0 and m["target_recall"] == 100.0 and m["first_match_precision"] == 100.0
    assert m["target_recall_seen"] is None  # no frame is "seen": undefined, not 0
    assert m["auroc_target"] == 1.0
    assert m["localisation_accuracy"] == 100.0 and m["localisation_point_precision"] == 50.0
    assert saved["ci95"]["tm_pct"] == [50.0, 50.0]  # one episode: every resample equals it
    md = (out / "metrics.md").read_text()
    assert "| stub@abc | 0.5 | matcher default | 100.00 | 50.00 | 50.00 | 0.00 |" in md
    assert "n/a" not in md.split("##")[0] and "sigma = 0.5 (matcher default)" in md
    tex = (out / "metrics.tex").read_text()
    assert r"\%Match" in tex and r"\caption{stub@abc, split val, sigma = 0.5 (matcher default).}" in tex
    per_cat = pd.read_csv(out / "per_category.csv", index_col="category")
    assert list(per_cat.index) == ["mug"] and per_cat.loc["mug", "tm_pct"] == 50.0
    assert result["files"] == {"metrics": str(out / "metrics.json"), "per_category": str(out / "per_category.csv"),
                               "markdown": str(out / "metrics.md"), "latex": str(out / "metrics.tex"),
                               "sigma_curves": str(out / "sigma_curves.png"),
                               "score_distributions": str(out / "score_distributions.png"),
                               "per_category_plot": str(out / "per_category.png"), "sizes": str(out / "sizes.csv"),
                               "page": str(out / "report.html")}  # no geometry here: no navigation files
    assert all(Path(path).stat().st_size > 0 for path in result["files"].values())


def test_report_threshold_sources(tiny_frameset, tmp_path):
    table = make_table(tiny_frameset, tmp_path)
    result = report(table, EvalContext(tiny_frameset, Bootstrap(n_boot=10)), tmp_path / "r", sigma=0.95)
    assert result["metrics"]["tm_pct"] is None  # nothing matched
    assert "| n/a |" in (tmp_path / "r" / "metrics.md").read_text()
    assert json.loads((tmp_path / "r" / "metrics.json").read_text())["sigma_source"] == "given"
    with pytest.raises(SigmaError, match="either"):
        report(table, tiny_frameset, tmp_path / "r", sigma=0.5, thresholds=tmp_path / "x.json")
    with pytest.raises(SigmaError, match="no thresholds file"):
        report(table, tiny_frameset, tmp_path / "r", thresholds=tmp_path / "x.json")
    table.meta["frameset_fingerprint"] = "0000"
    with pytest.raises(EvaluationError, match="computed on frame-set 0000"):
        report(table, tiny_frameset, tmp_path / "r", sigma=0.5)


def test_side_by_side_tables():
    rows = [report_row(dict(matcher_id="a@1", sigma=0.5, sigma_source="tuned: f1 on train",
                            metrics=dict(match_pct=55.74, tm_pct=55.33, cm_pct=42.0, nm_pct=2.67, auroc_target=0.91))),
            Row("b@2", 8.0, "matcher default", dict(match_pct=0.0, tm_pct=None))]
    table = side_by_side(rows)
    assert list(table.index) == ["a@1", "b@2"] and np.isnan(table.loc["b@2", "TM"])
    md = markdown_table(table)
    assert "| a@1 | 0.5 | tuned: f1 on train | 55.74 | 55.33 | 42.00 | 2.67 |" in md
    assert "| b@2 | 8 | matcher default | 0.00 | n/a |" in md
    tex = latex_table(table, caption="val")
    assert r"a@1 & 0.5 & tuned: f1 on train & 55.74 & 55.33 & 42.00 & 2.67" in tex and r"\caption{val}" in tex
    with pytest.raises(KeyError):  # a dict is not a row: side_by_side never guesses what it was given
        report_row(dict(matcher_id="c@3", sigma=1.0, metrics_at_sigma={}))


def _count_calls(monkeypatch, function) -> list:
    """Wrap ``function`` wherever pin_match.evaluation imported it by name; the list grows by one per call."""
    import sys

    calls = []

    def counting(*args, **kwargs):
        calls.append(args)
        return function(*args, **kwargs)

    for name, module in list(sys.modules.items()):
        if name.startswith("pin_match.evaluation") and getattr(module, function.__name__, None) is function:
            monkeypatch.setattr(module, function.__name__, counting)
    return calls


def test_bench_builds_labels_once_and_arrays_once_per_split(tiny_frameset, tmp_path, monkeypatch):
    """Two matchers, tuned on train and reported on val: one label table, one FrameArrays per matcher and split."""
    from pin_match.evaluation.core.metrics import frame_arrays
    from pin_match.evaluation.flows.bench import bench  # imported before the wrappers go in
    from pin_match.scoring import RunOptions

    labels = _count_calls(monkeypatch, frame_labels)
    arrays = _count_calls(monkeypatch, frame_arrays)
    done = bench(EvalContext(tiny_frameset, Bootstrap(n_boot=10)), ["color", "sift"], tmp_path,
                 run=RunOptions(workers=1, progress=False))
    assert len(labels) == 1
    assert len(arrays) == 2 * 2
    assert [r["matcher"] for r in done.results] == ["color", "sift"] and len(done.joint) == 2
    assert done.run.labels is done.run.context.labels and done.run.matchers == ["color", "sift"]


def test_a_shared_context_gives_the_numbers_of_a_fresh_one(tiny_frameset, tmp_path):
    """Tuning and reporting through one EvalContext (labels and arrays reused) equals each on its own."""
    table = make_table(tiny_frameset, tmp_path)
    shared = EvalContext(tiny_frameset, Bootstrap(n_boot=20))
    tuned = tune(table, shared)
    given = report(table, shared, tmp_path / "b", sigma=0.5)
    alone = report(table, EvalContext(tiny_frameset, Bootstrap(n_boot=20)), tmp_path / "a", sigma=0.5)
    assert (alone["metrics"], alone["ci95"]) == (given["metrics"], given["ci95"])
    assert tuned["metrics_at_sigma"] == tune(table, tiny_frameset)["metrics_at_sigma"]
    assert shared.scored(table, "val") is shared.scored(table, "val")


def test_bench_passes_its_tuned_choice_in_memory_and_a_default_run_leaves_no_stale_thresholds(tiny_frameset, tmp_path,
                                                                                            monkeypatch):
    from pin_match.evaluation.core.analysis import load_bench
    from pin_match.evaluation.flows import bench as bench_module
    from pin_match.evaluation.flows.bench import SigmaRule, bench
    from pin_match.scoring import RunOptions

    ctx, run = EvalContext(tiny_frameset, Bootstrap(n_boot=10)), RunOptions(workers=1, progress=False)
    reads = []
    monkeypatch.setattr(bench_module, "load_threshold", lambda *a: reads.append(a))
    tuned = bench(ctx, ["color"], tmp_path, run=run)
    assert reads == []  # the tuned sigma is not read back from its file
    path = tuned.run.layout.thresholds("color")
    assert json.loads(path.read_text())["sigma"] == tuned.run.tuned["color"]["sigma"] == tuned.results[0]["sigma"]
    untuned = bench(ctx, ["color"], tmp_path, sigma=SigmaRule("default"), run=run)
    assert not path.exists() and untuned.run.tuned == {}  # an earlier run's file is not this run's
    assert load_bench(tmp_path, tiny_frameset).tuned == {}


def test_a_thresholds_file_tuned_for_another_stop_policy_is_refused(tiny_frameset, tmp_path):
    """Issue 64, item 1: a sigma tuned for one stop policy was read for another without a word. A file records the
    policy it was tuned for (none: PIN's rule); reading it for another names the file and both policies."""
    from pin_match.evaluation.core.policies import tune_policy
    from pin_match.evaluation.core.sigma import PolicyMismatchError
    from pin_match.evaluation.core.stop import FIRST_MATCH, LookFurther

    table = make_table(tiny_frameset, tmp_path)
    pin = write_thresholds(tune(table, tiny_frameset), tmp_path / "pin.json")
    looked = write_thresholds(tune_policy(table, tiny_frameset, LookFurther(window=2)), tmp_path / "look.json")
    assert load_threshold(pin, "stub").value == 0.8 and load_threshold(looked, "stub", LookFurther(window=2))
    with pytest.raises(PolicyMismatchError, match=r"look\.json was tuned for stop policy look:2, not 1-of-1"):
        load_threshold(looked, "stub")
    with pytest.raises(PolicyMismatchError, match=r"pin\.json was tuned for stop policy 1-of-1, not look:2"):
        resolve_sigma("stub@1", None, thresholds=pin, policy=LookFurther(window=2))
    with pytest.raises(PolicyMismatchError, match="paper_thresholds.json was tuned for stop policy 1-of-1"):
        load_threshold("paper", "dinov2", LookFurther(window=20))
    with pytest.raises(PolicyMismatchError, match="look.json"):
        report(table, tiny_frameset, tmp_path / "r", thresholds=looked, policy=FIRST_MATCH)
