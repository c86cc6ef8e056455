"""verify: candidates from hand-made maps, colour on hand-made pixels, the file checks, the fit and the live matcher."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pin_match.contract import ConfigError, Crop, Frames, WeightsError, check_matcher, create_matcher
from pin_match.evaluation.core.labels import frame_labels
from pin_match.fitting.logistic import logistic_fit
from pin_match.fitting.verifier import (
    candidate_classes,
    candidate_table,
    fit_spec,
    fit_verifier,
    fit_weights,
    frame_scores,
    on_target,
    target_share,
)
from pin_match.fitting.verifier_report import candidate_lines, candidate_recall, signal_sets
from pin_match.matchers.common.candidates import (
    backprojection,
    bhattacharyya,
    cell_centre,
    color_histogram,
    locate,
    region_cells,
    shaped_box,
    square_around,
)
from pin_match.matchers.common.verifier_file import (
    DEFAULT_SIGNALS,
    SIGNALS,
    check_verifier,
    color_shortfall,
    read_verifier,
    verdict,
)
from pin_match.matchers.verify import DEFAULT_COLOR_GATE, VerifyMatcher
from pin_match.scoring import RunOptions

FAST = dict(signals=("proto", "margin", "desc", "color"), candidates=2)  # no keypoints: quick
QUIET = RunOptions(progress=False)


# ------------------------------------------------------------------ candidates
def test_region_is_the_connected_cells_near_the_peak():
    scores = np.array([[0.9, 0.85, 0.1],
                       [0.2, 0.82, 0.1],
                       [0.86, 0.1, 0.1]], np.float32)
    region = region_cells(scores, 0, 0, 0.1)
    # (2, 0) is within 0.1 of the peak but not connected to it
    assert region.tolist() == [[True, True, False], [False, True, False], [False, False, False]]


def test_shaped_box_grows_to_the_aspect_pads_and_stays_in_the_frame():
    # a 20 x 20 region, aspect 0.5 (tall): 20 x 40, padded by 25 % a side: 30 x 60, centred on (110, 110)
    assert shaped_box((100, 100, 120, 120), 0.5, 0.25, 10, (360, 640)) == (95, 80, 125, 140)
    # at the frame's corner the box is shifted in, not cut
    assert shaped_box((0, 0, 20, 20), 1.0, 0.0, 40, (360, 640)) == (0, 0, 40, 40)
    # never larger than the frame
    assert shaped_box((0, 0, 360, 600), 2.0, 0.5, 10, (360, 640)) == (0, 0, 360, 640)


def test_locate_orders_peaks_and_merges_cells_of_an_earlier_box():
    crops = [Crop(0, 0, 40, 40), Crop(0, 20, 40, 40)]  # two overlapping crops of a 60 x 40 frame, 4 x 4 cells
    maps = np.zeros((2, 4, 4), np.float32)
    maps[0, 2, 0] = 0.9   # cell centre (5, 25): a box of at least 2 cells, 20 px a side
    maps[1, 0, 0] = 0.8   # the same place seen by the second crop: inside the first box, skipped
    maps[1, 3, 3] = 0.7   # centre (35, 55): a second candidate
    found = locate(maps, crops, (60, 40), count=3, drop=0.05, aspect=1.0, pad=0.0)
    assert [c.peak for c in found[:2]] == pytest.approx([0.9, 0.7])
    assert found[0].box == (0, 15, 20, 35) and found[1].box == (20, 40, 40, 60)
    assert found[0].points.tolist() == [[5.0, 25.0]] and found[1].points.tolist() == [[35.0, 55.0]]
    assert len(found) == 3  # the third is the best cell outside both boxes (a zero)


def test_a_candidates_points_are_its_cells_best_first():
    maps = np.zeros((1, 4, 4), np.float32)
    maps[0, 0, 0], maps[0, 0, 1], maps[0, 1, 1] = 0.8, 0.9, 0.85  # one region; row-major order would put 0.8 first
    (found,) = locate(maps, [Crop(0, 0, 40, 40)], (40, 40), count=1, drop=0.2, aspect=1.0, pad=0.0)
    assert found.points.tolist() == [[15.0, 5.0], [15.0, 15.0], [5.0, 5.0]] and found.view is None


def test_a_zoom_cell_maps_back_into_its_box_and_a_square_fits_the_frame():
    # a 4 x 4 zoom grid squashed over a 40 x 80 box at (100, 200): cell 6 is row 1, column 2
    assert cell_centre((100, 200, 140, 280), 4, 6) == pytest.approx((125.0, 230.0))
    assert square_around((50.0, 50.0), 20, (360, 640)) == (40, 40, 60, 60)
    assert square_around((355.0, 2.0), 20, (360, 640)) == (340, 0, 360, 20)  # shifted in at the corner


def test_backprojection_marks_the_references_colour_by_how_rare_it_is_in_the_frame():
    frame = np.zeros((4, 8, 3), np.uint8)
    frame[:, :2, 0] = 220   # a quarter red
    frame[:, 2:, 2] = 220   # the rest blue
    bins = (16, 4, 4)
    red = color_histogram(frame[:, :2], np.ones((4, 2)), bins)  # the reference: all red
    weights = backprojection(frame, red, bins)
    # red: r = 1 / 0.25 = 4, weight 4 / 5; blue: not in the reference, 0
    assert weights[:, :2] == pytest.approx(np.full((4, 2), 0.8)) and not weights[:, 2:].any()


def test_colour_overlap_tells_red_from_blue_and_follows_the_weights():
    red = np.zeros((8, 8, 3), np.uint8)
    red[..., 0] = 220
    blue = red[..., ::-1].copy()
    ones = np.ones((8, 8))
    p, q = color_histogram(red, ones, (16, 4, 4)), color_histogram(blue, ones, (16, 4, 4))
    assert p.sum() == pytest.approx(1.0) and bhattacharyya(p, p) == pytest.approx(1.0)
    assert bhattacharyya(p, q) == pytest.approx(0.0)
    half = np.concatenate([red[:4], blue[4:]])
    weights = np.r_[np.ones(4), np.zeros(4)][:, None] * np.ones((1, 8))  # only the red half is the object
    assert bhattacharyya(color_histogram(half, weights, (16, 4, 4)), p) == pytest.approx(1.0)
    assert bhattacharyya(color_histogram(half, ones, (16, 4, 4)), p) == pytest.approx(np.sqrt(0.5))


# ------------------------------------------------------------------ fit rules
def test_a_candidate_is_on_the_target_by_share_or_fill():
    target = np.zeros((100, 100), bool)
    target[10:30, 10:30] = True  # 400 pixels
    assert on_target((0, 0, 20, 30), target)       # 200 of 400 inside: half of the target
    assert not on_target((0, 0, 15, 100), target)  # 100 inside: a quarter of the target, 7 % of the box
    assert on_target((25, 25, 35, 35), target)     # 25 inside a 100-pixel box: it fills a quarter
    assert not on_target((0, 0, 50, 50), np.zeros((100, 100), bool))
    assert target_share((0, 0, 20, 30), target) == pytest.approx(0.5) and target_share((0, 0, 5, 5), target) == 0.0


def test_candidate_classes_drop_off_target_candidates_of_target_frames_and_balance_classes():
    labels = pd.DataFrame(dict(frame_id=["t", "s", "o"], target_visible=[True, False, False],
                               same_visible=[False, True, False], other_visible=[False, False, True]))
    table = pd.DataFrame(dict(frame_id=["t", "t", "s", "s", "o"], on_target=[True, False, False, False, False]))
    used, weights, counts = candidate_classes(table, labels)
    assert used.frame_id.tolist() == ["t", "s", "s", "o"]
    assert weights.tolist() == [1.0, 0.5, 0.5, 1.0]
    assert counts == {"target": 1, "same_category": 2, "other": 1}


# ------------------------------------------------------------------ the report's pieces
def test_candidate_recall_counts_target_frames_that_some_box_covers_by_half():
    labels = pd.DataFrame(dict(frame_id=["a", "b", "c", "d"], target_visible=[True, True, True, False]))
    table = pd.DataFrame(dict(frame_id=["a", "a", "b", "d"], cover=[0.2, 0.6, 0.4, 0.0]))
    # a: its second box holds 60 %; b: 40 % at best; c: no candidate at all; d shows no target
    assert candidate_recall(table, labels) == pytest.approx(1 / 3)


def test_ablation_rows_without_colour_have_no_gate_and_the_default_is_also_read_ungated():
    rows = signal_sets()
    assert rows["default"] == dict(signals=DEFAULT_SIGNALS)
    assert rows["default, no gate"] == dict(signals=DEFAULT_SIGNALS, color_gate=0.0)
    assert rows["proto alone"] == dict(signals=("proto",), color_gate=0.0)
    assert rows["without keypoints"] == dict(signals=DEFAULT_SIGNALS)
    for overrides in rows.values():
        create_matcher("verify", **overrides)  # every row is a valid configuration


def test_each_candidate_says_why_it_decided():
    spec = dict(intercept=0.0, coefs={"proto": 1.0, "color": 1.0}, gate=dict(floor=0.5, coef=10.0))
    cands = pd.DataFrame(dict(candidate=[0, 1], proto=[0.5, 0.5], color=[0.2, 0.5]))
    probabilities, lines = candidate_lines(cands, spec)
    assert probabilities == pytest.approx([1 / (1 + np.exp(2.3)), 1 / (1 + np.exp(-1.0))])  # 0.7 - 3.0; 1.0
    assert lines[0] == "#0 p 0.09, colour gated\n  pr 0.50 co 0.20" and lines[1] == "#1 p 0.73\n  pr 0.50 co 0.50"


# ------------------------------------------------------------------ the file
def verifier_file(path, signals_id, coefs, intercept=-1.0, gate=None):
    gate = gate or dict(floor=DEFAULT_COLOR_GATE if "color" in coefs else 0.0, coef=5.0)
    path.write_text(json.dumps(dict(format="pin-match-verifier", version=2, signals_id=signals_id,
                                    intercept=intercept, coefs=coefs, gate=gate)))
    return path


def test_verdict_is_the_logistic_of_the_file():
    spec = dict(intercept=-1.0, coefs={"proto": 2.0, "color": 4.0}, gate=dict(floor=0.0, coef=0.0))
    assert verdict(spec, {"proto": 0.5, "color": 0.25}) == pytest.approx(1 / (1 + np.exp(-1.0)))


def test_the_colour_gate_only_subtracts_below_its_floor():
    spec = dict(intercept=-1.0, coefs={"proto": 2.0, "color": 4.0}, gate=dict(floor=0.5, coef=10.0))
    # colour 0.25 is 0.25 short of the floor: logit -1 + 1 + 1 - 10 x 0.25 = -1.5
    assert verdict(spec, {"proto": 0.5, "color": 0.25}) == pytest.approx(1 / (1 + np.exp(1.5)))
    # at or above the floor the gate adds nothing: -1 + 1 + 2.4 = 2.4
    assert verdict(spec, {"proto": 0.5, "color": 0.6}) == pytest.approx(1 / (1 + np.exp(-2.4)))
    assert color_shortfall(0.7, 0.5) == 0.0 and color_shortfall(0.2, 0.5) == pytest.approx(-0.3)


def test_the_penalty_subtracts_at_most_its_slope_times_the_floor():
    spec = dict(intercept=0.0, coefs={"proto": 1.0, "color": 0.0}, gate=dict(floor=0.8, coef=2.0))
    logit = [np.log(p / (1 - p)) for p in (verdict(spec, {"proto": 1.0, "color": c}) for c in (0.0, 0.8, 1.0))]
    assert logit == pytest.approx([1.0 - 2.0 * 0.8, 1.0, 1.0])  # a bounded penalty, no veto: still above 0.5


def test_a_negative_colour_weight_or_penalty_slope_is_refused_naming_the_file(tmp_path):
    signals = {"proto": 1.0, "color": 1.0}
    negative_gate = verifier_file(tmp_path / "negative_gate.json", "x", signals, gate=dict(floor=0.8, coef=-0.5))
    with pytest.raises(WeightsError, match=r"negative_gate\.json: gate\.coef is -0\.5.*colour mismatch would raise"):
        read_verifier(negative_gate)
    negative_colour = verifier_file(tmp_path / "negative_colour.json", "x", {"proto": 1.0, "color": -0.1})
    with pytest.raises(WeightsError, match=r"negative_colour\.json: coefs\.color is -0\.1.*colour mismatch"):
        read_verifier(negative_colour)
    zero = verifier_file(tmp_path / "zero.json", "x", {"proto": 1.0, "color": 0.0}, gate=dict(floor=0.8, coef=0.0))
    assert read_verifier(zero)["gate"]["coef"] == 0.0  # 0 is allowed: colour then does not count


def carried_spec() -> dict:
    return read_verifier(VerifyMatcher.weights_spec.resolve(None, "verify"))


def test_the_carried_file_weighs_colour_up_and_passes_the_sign_check():
    spec = carried_spec()
    assert spec["coefs"]["color"] == pytest.approx(1.64, abs=0.005) and spec["coefs"]["color"] > 0
    assert spec["gate"] == pytest.approx(dict(floor=0.8, coef=1.63), abs=0.005) and spec["gate"]["coef"] > 0


COLOURS = sorted({*np.linspace(0.0, 1.0, 101).tolist(), DEFAULT_COLOR_GATE})  # the floor itself on the grid
OTHER_SIGNALS = st.fixed_dictionaries({s: st.floats(-1.0, 1.0) for s in SIGNALS if s != "color"})


@settings(max_examples=50, deadline=None)
@given(others=OTHER_SIGNALS)
def test_lowering_colour_never_raises_the_carried_files_verdict(others):
    spec = carried_spec()
    scores = [verdict(spec, {**others, "color": c}) for c in COLOURS]
    assert all(lower <= higher for lower, higher in zip(scores, scores[1:]))


@st.composite
def verifier_specs(draw):
    """Any spec with whole fields, whatever the signs of its coefficients."""
    weight = st.floats(-10.0, 10.0)
    signals = draw(st.lists(st.sampled_from(SIGNALS), min_size=1, unique=True))
    floor = draw(st.one_of(st.just(0.0), st.floats(0.01, 0.99))) if "color" in signals else 0.0
    return dict(intercept=draw(weight), coefs={s: draw(weight) for s in signals},
                gate=dict(floor=floor, coef=draw(weight)))


@settings(max_examples=300, deadline=None)
@given(spec=verifier_specs(), others=OTHER_SIGNALS, colours=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)))
def test_a_spec_the_reader_accepts_never_rewards_a_colour_mismatch(spec, others, colours):
    try:
        check_verifier(spec, Path("random.json"))
    except WeightsError as exc:  # refused only for a negative colour weight or slope, by name
        assert spec["coefs"].get("color", 0.0) < 0 or spec["gate"]["coef"] < 0
        assert "random.json" in str(exc) and "a colour mismatch would raise the probability" in str(exc)
        return
    low, high = sorted(colours)
    assert verdict(spec, {**others, "color": low}) <= verdict(spec, {**others, "color": high})


def test_a_fit_where_colour_misleads_keeps_it_at_zero_and_fits_the_rest():
    rng = np.random.default_rng(0)
    y = np.r_[np.ones(150), np.zeros(250)]
    used = pd.DataFrame(dict(on_target=y.astype(bool), proto=0.4 * y + rng.normal(0.3, 0.2, 400),
                             desc=0.3 * y + rng.normal(0.5, 0.2, 400),
                             color=np.clip(0.95 - 0.35 * y + rng.normal(0.0, 0.1, 400), 0.0, 1.0)))
    weights = np.where(y == 1, 1 / 150, 1 / 250)
    signals, floor = ("proto", "desc", "color"), DEFAULT_COLOR_GATE
    x = np.c_[used[list(signals)].to_numpy(), [color_shortfall(c, floor) for c in used.color]]
    free = logistic_fit(x, y, weights, 1.0)
    assert free[3] < 0 and free[4] < 0  # unconstrained, a colour mismatch would raise the probability
    fitted = fit_weights(used, weights, signals, floor, 1.0)
    assert fitted["coefs"]["color"] == 0.0 and fitted["gate"]["floor"] == floor and fitted["gate"]["coef"] >= 0.0
    # the others are refitted without the colour terms held at 0: the fit of proto and desc alone
    values = [*fitted["coefs"].values(), fitted["gate"]["coef"]]
    kept = [j for j, c in enumerate(values) if c != 0.0]
    assert kept[:2] == [0, 1]
    refit = logistic_fit(x[:, kept], y, weights, 1.0)
    assert [fitted["intercept"], *(values[j] for j in kept)] == pytest.approx(refit.tolist(), rel=1e-9)
    assert fitted["coefs"]["proto"] > 1.0 and fitted["coefs"]["desc"] > 1.0


def test_bad_files_and_configs_are_refused_by_name(tmp_path):
    with pytest.raises(ConfigError, match="signals="):
        create_matcher("verify", signals=("proto", "shape"))
    with pytest.raises(ConfigError, match="color_bins"):
        create_matcher("verify", color_bins=(16, 4))
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    with pytest.raises(WeightsError, match="bad.json"):
        read_verifier(bad)
    with pytest.raises(WeightsError, match="finite 'intercept'"):
        read_verifier(verifier_file(tmp_path / "v.json", "x", {"shape": 1.0}))
    with pytest.raises(WeightsError, match="above 0 only with color"):  # a gate on a colour the file never weighs
        read_verifier(verifier_file(tmp_path / "v.json", "x", {"proto": 1.0}, gate=dict(floor=0.5, coef=1.0)))
    with pytest.raises(ConfigError, match="color_gate"):
        create_matcher("verify", signals=("proto", "desc"))
    gated = verifier_file(tmp_path / "gated.json", create_matcher("verify", **FAST).signals_id,
                          {s: 1.0 for s in FAST["signals"]}, gate=dict(floor=0.3, coef=1.0))
    with pytest.raises(WeightsError, match="colour gate 0.3"):
        _ = create_matcher("verify", weights=str(gated), **FAST).decision
    matcher = create_matcher("verify", **FAST)
    stale = verifier_file(tmp_path / "stale.json", "000000000000", {s: 1.0 for s in FAST["signals"]})
    with pytest.raises(WeightsError, match="stale.json was fitted on .*refit"):
        _ = create_matcher("verify", weights=str(stale), **FAST).decision
    other = verifier_file(tmp_path / "other.json", matcher.signals_id, {"proto": 1.0})
    with pytest.raises(WeightsError, match="other.json was fitted on signals"):
        _ = create_matcher("verify", weights=str(other), **FAST).decision


def test_the_id_hashes_the_file_and_the_signals_id_does_not(tmp_path):
    matcher = create_matcher("verify", **FAST)
    path = verifier_file(tmp_path / "v.json", matcher.signals_id, {s: 1.0 for s in FAST["signals"]})
    first = create_matcher("verify", weights=str(path), **FAST).id
    verifier_file(path, matcher.signals_id, {s: 2.0 for s in FAST["signals"]})
    second = create_matcher("verify", weights=str(path), **FAST)
    assert first != second.id and second.signals_id == matcher.signals_id
    assert create_matcher("verify", **{**FAST, "zoom_size": 224}).signals_id != matcher.signals_id
    # the gate decides from the same signals: another floor, the same cached table
    assert create_matcher("verify", **{**FAST, "color_gate": 0.0}).signals_id == matcher.signals_id


# ------------------------------------------------------------------ fit and live matcher
def test_fit_on_the_tiny_set_and_the_live_scores_are_the_cached_signals_fused(tiny_frameset, tmp_path):
    every = dict(candidates=2, signals=SIGNALS)  # keypoints included
    features = tmp_path / "features"
    spec = fit_verifier([tiny_frameset], tmp_path / "all.json", split="train", overrides=every, out=features,
                        run=QUIET)
    assert spec["fitted_on"]["classes"]["target"] >= 1 and set(spec["coefs"]) == set(SIGNALS)
    assert spec["gate"]["floor"] == DEFAULT_COLOR_GATE and spec["gate"]["coef"] != 0.0
    (train_chunk,) = features.rglob("chunks/ep_train.parquet")
    written = train_chunk.stat().st_mtime_ns
    # an ablation reads the one table of every signal: the train episode's chunk is not computed again
    table = candidate_table(tiny_frameset, create_matcher("verify", **every), out=features, run=QUIET)
    assert train_chunk.stat().st_mtime_ns == written and set(table.frame_id) == set(tiny_frameset.frames.frame_id)
    val = tiny_frameset.split("val")  # a view of one split is that split's table, never passed off as the whole set's
    assert set(candidate_table(val, create_matcher("verify", **every), out=features, run=QUIET).episode_id) \
        == set(val.episodes.episode_id)
    assert sorted(p.name for p in train_chunk.parent.parent.glob("*.parquet")) \
        == ["candidates_all.parquet", "candidates_train.parquet", "candidates_val.parquet"]
    matcher = create_matcher("verify", **FAST)
    spec = fit_spec(matcher, [(tiny_frameset, frame_labels(tiny_frameset), table)], "train", 1.0)
    assert set(spec["coefs"]) == set(FAST["signals"])
    path = tmp_path / "v.json"
    path.write_text(json.dumps(spec))
    matcher = create_matcher("verify", weights=str(path), **FAST)
    cached = dict(zip(*frame_scores(table, spec).T.to_numpy()))
    episode = tiny_frameset.episodes.iloc[1]
    matcher.prepare(tiny_frameset.target(episode.target_object_id))
    ids = list(tiny_frameset.frames.frame_id[tiny_frameset.frames.episode_id == episode.episode_id])
    results = matcher.match_batch([tiny_frameset.image(f) for f in ids])
    assert [r.score for r in results] == pytest.approx([cached[f] for f in ids], abs=1e-6)
    for r in results:
        assert 0.0 < r.score < 1.0 and r.score == pytest.approx(float(r.box_scores.max()))
        assert len(r.points_at(r.score)) >= 1 and len(r.points_at(r.score + 1e-3)) == 0
    target_frame = results[0]  # frame 0 shows the target, a disc at (100, 300) + 96 px
    x0, y0, x1, y1 = target_frame.boxes[int(np.argmax(target_frame.box_scores))]
    assert x0 <= 148 <= x1 and y0 <= 348 <= y1
    # the best point (the first: the second zoom's) lies on the disc, and each box names a reference view
    assert np.hypot(*(target_frame.points[0] - [148, 348])) <= 48
    assert target_frame.box_views.shape == target_frame.box_scores.shape
    assert set(target_frame.box_views.tolist()) <= {0, 1, 2}


def test_the_second_zoom_runs_on_frames_at_its_floor_only_and_moves_no_score(tiny_frameset, monkeypatch):
    """The closer zoom only moves the first point: under ``refine_floor`` a frame keeps every score and box of the
    whole run, and its points are the whole run's without the refined one in front."""
    episode = tiny_frameset.episodes.iloc[1]
    ids = list(tiny_frameset.frames.frame_id[tiny_frameset.frames.episode_id == episode.episode_id])
    images = [tiny_frameset.image(f) for f in ids]
    every = create_matcher("verify", refine_floor=0.0)
    every.prepare(tiny_frameset.target(episode.target_object_id))
    whole = every.match_batch(images)
    scores = sorted(r.score for r in whole)
    floor = (scores[1] + scores[2]) / 2  # two frames on each side
    gated = create_matcher("verify", refine_floor=floor)
    assert gated.id != every.id and gated.signals_id == every.signals_id  # one cached table of signals for both
    gated.prepare(tiny_frameset.target(episode.target_object_id))
    zoomed, refined = [], VerifyMatcher._refined
    monkeypatch.setattr(VerifyMatcher, "_refined", lambda self, im, best: zoomed.append(len(im)) or refined(
        self, im, best))
    for a, b in zip(whole, gated.match_batch(images)):
        assert b.score == a.score and np.array_equal(b.boxes, a.boxes) and np.array_equal(b.box_scores, a.box_scores)
        assert np.array_equal(b.points, a.points if a.score >= floor else a.points[1:])
        assert np.array_equal(b.point_scores, a.point_scores if a.score >= floor else a.point_scores[1:])
    assert zoomed == [2]
    with pytest.raises(ConfigError, match="refine_floor"):
        create_matcher("verify", refine_floor=1.5)


def test_locate_signals_alone_need_no_second_pass(tiny_frameset, tmp_path):
    locate_only = dict(signals=("proto", "margin"), color_gate=0.0)
    matcher = create_matcher("verify", **locate_only)
    path = verifier_file(tmp_path / "v.json", matcher.signals_id, {"proto": 4.0, "margin": 1.0}, intercept=-2.0)
    matcher = create_matcher("verify", weights=str(path), **locate_only)
    episode = tiny_frameset.episodes.iloc[0]
    matcher.prepare(tiny_frameset.target(episode.target_object_id))
    zoom_passes = []
    matcher.zoomer.backbone.encode = lambda crops: zoom_passes.append(len(crops))
    effnet = create_matcher("effnet")
    effnet.prepare(tiny_frameset.target(episode.target_object_id))
    image = tiny_frameset.image(tiny_frameset.frames.frame_id.iloc[0])
    (rows,) = matcher.candidate_signals(Frames([image]))
    assert zoom_passes == [] and rows[0][1]["proto"] == pytest.approx(effnet.match(image).score, abs=1e-6)
    assert rows[0][0].view is None  # no zoom, no view: the result then has no box views


def test_prepare_prepares_the_locate_part_and_the_keypoint_part_only_when_its_signal_is_used(tiny_frameset,
                                                                                            monkeypatch):
    """The zoom part lends verify its network (the references are cut and embedded by verify itself), and the
    keypoint part is built for the id but used only with its signal: neither is prepared for nothing."""
    from pin_match.contract import Matcher

    prepared, original = [], Matcher.prepare
    monkeypatch.setattr(Matcher, "prepare", lambda self, target: prepared.append(self) or original(self, target))
    target = tiny_frameset.target(tiny_frameset.episodes.target_object_id.iloc[0])
    default = create_matcher("verify")
    default.prepare(target)
    assert prepared == [default, default.locator]
    prepared.clear()
    every = create_matcher("verify", signals=SIGNALS)
    every.prepare(target)
    assert prepared == [every, every.locator, every.keypointer]
    assert default.reference.descriptors.norm(dim=-1).sub(1).abs().max() < 1e-6  # unit length, compared as they are


def test_contract_with_real_weights(tmp_path):
    matcher = create_matcher("verify", **FAST)
    path = verifier_file(tmp_path / "v.json", matcher.signals_id, {s: 1.0 for s in FAST["signals"]})
    scores = check_matcher("verify", weights=str(path), **FAST)
    assert all(0.0 < s < 1.0 for s in scores.values())
    assert all(0.0 < s < 1.0 for s in check_matcher("verify").values())  # the default: carried file, offline


def test_the_carried_verifier_file_fits_the_default_signals():
    """The shipped file records the signals id it was fitted for; a change that moves it (a new hashed config
    field, a bump of SIGNALS_VERSION, new weights of a part) makes ``verify`` refuse the file, so such a change must
    refit it."""
    matcher = create_matcher("verify")
    assert matcher.decision["signals_id"] == matcher.signals_id
    assert set(matcher.decision["coefs"]) == set(DEFAULT_SIGNALS)


def test_the_carried_verifier_file_is_under_the_projects_licence():
    """Issue 43.1: the file was fitted by pin_match, so it comes under pin_match's licence (MIT), not Apache-2.0."""
    from importlib.metadata import metadata

    from pin_match.matchers.verify import VerifyMatcher

    project = metadata("pin-match")["License"]
    assert project == "MIT"
    assert f"({project})" in VerifyMatcher.weights_spec.license and "Apache" not in VerifyMatcher.weights_spec.license




def test_a_candidate_signal_run_cut_off_resumes_from_its_chunks(tiny_frameset, tmp_path, monkeypatch):
    matcher = create_matcher("verify", **FAST)
    original, seen = VerifyMatcher.candidate_signals, []

    def cut_off_at_the_second_target(self, images):
        seen.append(self.reference)
        if len(seen) > 1 and seen[-1] is not seen[0]:
            raise KeyboardInterrupt  # the run is killed in its second episode
        return original(self, images)

    monkeypatch.setattr(VerifyMatcher, "candidate_signals", cut_off_at_the_second_target)
    with pytest.raises(KeyboardInterrupt):
        candidate_table(tiny_frameset, matcher, out=tmp_path, run=QUIET)
    (done,) = tmp_path.rglob("chunks/*.parquet")
    assert not list(tmp_path.rglob("candidates_*.parquet"))  # nothing half-written
    episodes = []
    monkeypatch.setattr(VerifyMatcher, "candidate_signals",
                        lambda self, images: episodes.append(self.reference) or original(self, images))
    table = candidate_table(tiny_frameset, matcher, out=tmp_path, run=QUIET)
    assert len({id(r) for r in episodes}) == 1  # only the episode without a chunk is computed again
    assert set(table.episode_id) == set(tiny_frameset.episodes.episode_id) and done.stem in set(table.episode_id)


def test_verifier_report_runs_end_to_end_and_keys_sets_by_their_path(tiny_frameset, tmp_path, capsys):
    import shutil

    from pin_match.cli import main

    twin = tmp_path / "b" / tiny_frameset.root.name  # another folder of the same name
    shutil.copytree(tiny_frameset.root, twin)
    out = tmp_path / "report.json"
    code = main(["fit", "verifier-report", "--train", str(tiny_frameset.root), "--eval", str(tiny_frameset.root),
                 f"{twin}:val", "--features", str(tmp_path / "features"), "--json", str(out),
                 "--figure", str(tmp_path / "fig.png"), "--quiet"])
    assert code in (0, None)
    result = json.loads(out.read_text())
    assert {r["set"] for r in result["rows"]} == {str(tiny_frameset.root), f"{twin}:val"}
    labels = {r["matcher"] for r in result["rows"]}
    assert {"effnet", "verify default", "verify default, no gate", "verify proto alone"} <= labels
    assert not any("keypoints" in label for label in labels)  # rows only of the signals computed
    assert (tmp_path / "fig.png").stat().st_size > 0


def test_a_fit_with_nothing_to_fit_on_is_refused(tiny_frameset):
    from pin_match.fitting.logistic import FitError

    matcher = create_matcher("verify", **FAST)
    with pytest.raises(FitError, match="no frame-set"):
        fit_spec(matcher, [], "train", 1.0)
    empty = pd.DataFrame(columns=["frame_id", "split", "on_target", *FAST["signals"]])
    with pytest.raises(FitError, match="no candidate in split 'train'"):
        fit_spec(matcher, [(tiny_frameset, frame_labels(tiny_frameset), empty)], "train", 1.0)
