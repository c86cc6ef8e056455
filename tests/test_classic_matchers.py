"""The weight-free matchers find the target: scores rank target > same-category look-alike > nothing.

Measured on the default frame-set of ``pin-match synth``: real scanned products (Google Scanned
Objects) in look-alike families, rendered along PIN walks (exact ground truth, same bytes for the
seed), by mean score per frame class: frames showing the target; frames showing a look-alike of
its family but not the target; frames showing no annotated object at all. SIFT needs ``min_inliers``
verified matches, which the renders rarely give (at least 5 target frames, at most 0.1 % of the frames
showing nothing annotated), so for it look-alike and nothing may tie near 0. The real-photo tests check SIFT's floor
and colour's saturation (issue 14.10, 14.11).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from conftest import make_view
from pin_match import Target, create_matcher
from pin_match.evaluation.core.labels import frame_labels, scored_frames
from pin_match.scoring import RunOptions, score

# sift's share of frames showing nothing annotated that it verifies: generator 10's default sets of seeds 0-4 gave
# 0-2 of 7,935-8,877 (0.023 % at most: seed 0's 2, at 6 inliers), generator 7's 1 of 1,797 (a colour double wearing
# its object's own print); and 30-38 target frames at 5 inliers or more
NOTHING_VERIFIED = 0.001


def _frame_classes(fs, table):
    """The scores and the frames showing the target; a look-alike of its family but not the target; nothing
    annotated at all."""
    scored = scored_frames(frame_labels(fs), table)
    target = scored.target_visible
    return scored.score, target, ~target & scored.same_visible, ~target & ~scored.same_visible & ~scored.other_visible


@pytest.mark.parametrize("name", ["sift", "color"])
def test_scores_rank_target_above_lookalikes_above_nothing(name, default_synth, tmp_path):
    score_of, target, lookalike, nothing = _frame_classes(
        default_synth, score(default_synth, name, out=tmp_path, run=RunOptions(progress=False)))
    assert min(target.sum(), lookalike.sum(), nothing.sum()) >= 50
    means = [score_of[m].mean() for m in (target, lookalike, nothing)]
    message = f"{name}: target {means[0]:.3f}, look-alike {means[1]:.3f}, nothing {means[2]:.3f}"
    if name == "color":
        assert means[0] > means[1] > means[2], message
    else:  # sift verifies a model only with min_inliers: rarely on these renders, never by chance
        assert means[0] > max(means[1], means[2]), message
        assert (score_of[nothing] > 0).mean() <= NOTHING_VERIFIED and (score_of[target] >= 5).sum() >= 5


@pytest.mark.slow
def test_sift_verifies_an_unannotated_twin_of_an_object(monkeypatch, tmp_path):
    """A broken generator whose clutter is a copy of each annotated object, left unannotated, gives frames showing
    nothing annotated that sift verifies, above the bar (a val house of seed 0: 6 of 849, 0.7 %, where the bar once
    allowed 1 %)."""
    import importlib

    from pin_match.data.synth import SynthSize, generate

    monkeypatch.setattr(importlib.import_module("pin_match.data.synth.generator"), "choose_scanned",
                        lambda pool, house, rng: list(house))
    fs = generate(tmp_path / "fs", SynthSize(episodes=6, splits=("val",)), workers=1)
    score_of, _, _, nothing = _frame_classes(fs, score(fs, "sift", out=tmp_path / "scores",
                                                       run=RunOptions(progress=False)))
    assert (score_of[nothing] > 0).mean() > NOTHING_VERIFIED, np.sort(score_of[nothing])[-5:]


def test_sift_verified_points_lie_on_the_pasted_object():
    rng = np.random.default_rng(0)
    view = make_view((200, 30, 30), size=160)
    view[..., :3] = np.where(view[..., 3:] > 0, rng.integers(0, 256, view[..., :3].shape, dtype=np.uint8), 0)
    m = create_matcher("sift")
    m.prepare(Target("o", "toy", (view, view, view), ("a", "b", "c")))
    frame = rng.integers(0, 60, (640, 360, 3), dtype=np.uint8)
    alpha = view[..., 3] > 0
    frame[300:460, 100:260][alpha] = view[..., :3][alpha]
    r = m.match(frame)
    assert r.score >= 20  # a textured object pasted unchanged is verified with many inliers
    pts = r.points_at(r.score)
    assert len(pts) >= 20 and (pts[:, 0] >= 100).all() and (pts[:, 0] < 260).all()
    assert (pts[:, 1] >= 300).all() and (pts[:, 1] < 460).all()
    assert m.match(np.full((640, 360, 3), 90, np.uint8)).score == 0.0  # nothing to match


def test_color_window_centres_on_the_object():
    view = make_view((30, 160, 220))
    m = create_matcher("color")
    m.prepare(Target("o", "ball", (view, view, view), ("a", "b", "c")))
    frame = np.full((640, 360, 3), (120, 110, 90), np.uint8)
    frame[450:546, 200:296][view[..., 3] > 0] = (30, 160, 220)
    r = m.match(frame)
    best = r.points[np.argmax(r.point_scores)]
    assert abs(best[0] - 248) < 25 and abs(best[1] - 498) < 25
    assert r.crop_scores[1] == pytest.approx(r.score) and r.crop_scores[0] < r.score  # only the lower crop sees it


# ---------------------------------------------------------------- real photos (issue 14.10, 14.11)
def _photo_target() -> tuple[Target, np.ndarray]:
    """The cat's head from scikit-image's ``chelsea`` photo as a 3-view target, and a real photo without it."""
    data = pytest.importorskip("skimage.data")
    cat = data.chelsea()[40:200, 120:300]  # 160 x 180 px
    view = np.dstack([cat, np.full(cat.shape[:2], 255, np.uint8)])
    scene = np.ascontiguousarray(data.coffee()[:, 100:460])[:400]  # 400 x 360: a cup, a saucer, a table
    return Target("cat", "cat", (view, view, view), ("a", "b", "c")), scene


def test_sift_has_no_floor_of_two_on_a_real_photo_without_the_target():
    """Any 2 matches fit a similarity exactly; with min_inliers they no longer score."""
    target, scene = _photo_target()
    frame = np.zeros((640, 360, 3), np.uint8)
    frame[:400] = scene
    loose = create_matcher("sift", min_inliers=2)  # the old rule
    loose.prepare(target)
    assert loose.match(frame).score >= 2  # chance models on real texture
    strict = create_matcher("sift")
    strict.prepare(target)
    assert strict.match(frame).score == 0.0 and len(strict.match(frame).points) == 0
    frame[420:580, 90:270] = target.views[0][..., :3]  # the cat pasted below the cup
    found = strict.match(frame)
    assert found.score >= strict.default_sigma and (found.points[:, 1] >= 420).all()


def test_color_score_is_continuous_at_the_top():
    """Two pastes of the same real object at different sizes: Swain & Ballard's min(r, 1) gives both 1.0."""
    target, scene = _photo_target()
    m = create_matcher("color", crops="whole")
    m.prepare(target)
    cat = target.views[0][..., :3]
    scores, clipped = [], []
    for size in (90, 160):
        frame = cv2.resize(scene, (360, 640))
        patch = cv2.resize(cat, (size * 180 // 160, size), interpolation=cv2.INTER_AREA)
        frame[300:300 + size, 60:60 + patch.shape[1]] = patch
        scores.append(m.match(frame).score)
        small = cv2.resize(frame, (m.cfg.work_size, m.cfg.work_size), interpolation=cv2.INTER_AREA)
        bins = m._bins(small)
        weight = np.minimum(m._model / np.maximum(m._hist(bins), 1e-12), 1.0)[bins]
        clipped.append(max(cv2.boxFilter(weight, -1, (k, k)).max() for k in m.cfg.windows))
    assert clipped == [pytest.approx(1.0), pytest.approx(1.0)]  # the old weight saturates on both
    assert all(0.5 < s < 1.0 for s in scores) and scores[0] != scores[1]


def test_color_separates_colour_look_alikes_of_the_default_set_better_than_print_ones(default_synth, tmp_path):
    """On the default set's val split, `color` tells a target from a sibling of another colour better than from
    a sibling with another print (measured 0.813 against 0.615 at generator version 7, 0.760 against 0.635 at
    version 5, 0.891 against 0.634 at version 4: docs/synthetic.md), as on real photos it separates
    recolours and not prints. Kinds are each target's `difference` in the shipped families.csv."""
    import pandas as pd

    from pin_match.data.synth.scans import PACKAGED_SCANS
    from pin_match.evaluation.core.metrics import auroc

    kind = pd.read_csv(PACKAGED_SCANS / "families.csv").set_index("scan").difference
    table = score(default_synth, "color", out=tmp_path, split="val", run=RunOptions(progress=False))
    scored = scored_frames(frame_labels(default_synth), table)
    targets = default_synth.episodes.set_index("episode_id").target_object_id
    scored["kind"] = scored.episode_id.map(targets).map(kind)
    result = {}
    for k in ("colour", "print"):
        frames = scored[scored.kind == k]
        lookalike = ~frames.target_visible & frames.same_visible
        result[k] = auroc(frames.score[frames.target_visible].to_numpy(), frames.score[lookalike].to_numpy())
    assert result["colour"] > 0.72 and result["colour"] - result["print"] > 0.08, result
