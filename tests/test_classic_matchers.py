"""The weight-free matchers find the target: scores rank target > same-category look-alike > nothing.

Measured on the demo's default synthetic frame-set (exact ground truth, same bytes for the
seed), by mean score per frame class: frames showing the target; frames showing a
same-category distractor but not the target; frames showing no object at all. Small
frame-sets hold too few look-alike frames for SIFT's sparse evidence to rank reliably.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_view
from pin_match import Target, create_matcher
from pin_match.labels import frame_labels, scored_frames
from pin_match.scoring import score
from pin_match.synth import DEFAULTS, generate


@pytest.fixture(scope="module")
def ranking_set(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("synth_rank") / "frameset", workers=2, **DEFAULTS)


@pytest.mark.parametrize("name", ["sift", "color"])
def test_scores_rank_target_above_lookalikes_above_nothing(name, ranking_set, tmp_path):
    scored = scored_frames(frame_labels(ranking_set), score(ranking_set, name, out=tmp_path, progress=False))
    target = scored.target_visible
    lookalike = ~target & scored.same_visible
    nothing = ~target & ~scored.same_visible & ~scored.other_visible
    assert min(target.sum(), lookalike.sum(), nothing.sum()) >= 50
    means = [scored.score[m].mean() for m in (target, lookalike, nothing)]
    assert means[0] > means[1] > means[2], f"{name}: target {means[0]:.3f}, look-alike {means[1]:.3f}, " \
                                            f"nothing {means[2]:.3f}"


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
