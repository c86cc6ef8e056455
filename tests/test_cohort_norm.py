"""Cohort normalisation: the statistics by hand, the wrapper keeps its base's ranking and points, the cohort's id."""

from __future__ import annotations

import numpy as np
import pytest

from pin_match import atomic
from pin_match.contract import ConfigError, WeightsError, create_matcher
from pin_match.contract.cohort import Impostors, logit


def test_adaptive_statistics_take_the_k_highest_and_floor_the_spread():
    scores = [0.1, 0.2, 0.5, 0.9]
    top2 = logit(np.array([0.9, 0.5]))
    stats = Impostors.of(scores, k=2)
    assert stats.mean == pytest.approx(top2.mean()) and stats.std == pytest.approx(top2.std())
    assert Impostors.of(scores).mean == pytest.approx(logit(np.array(scores)).mean())  # k 0: plain Z-norm
    flat = Impostors.of([0.3, 0.3, 0.3], min_std=0.25)
    assert flat.std == 0.25 and flat.normalised(0.3) == pytest.approx(0.5)
    raw = Impostors.of([1.0, 3.0], probability=False)  # a score that is no probability: as it is
    assert (raw.mean, raw.std) == (2.0, 1.0) and raw.normalised(3.0) == pytest.approx(1 / (1 + np.exp(-1)))
    with pytest.raises(ValueError, match="at least one"):
        Impostors.of([])


def test_the_normalised_score_is_monotone_and_stays_in_the_unit_interval():
    stats = Impostors.of([0.2, 0.6, 0.7], k=2)
    values = stats.normalised(np.linspace(0.0, 1.0, 101))
    assert np.all(np.diff(values) >= 0) and values.min() >= 0.0 and values.max() <= 1.0
    assert 0.0 < stats.normalised(0.4) < stats.normalised(0.6) < 1.0


def _cohort(folder, colours):
    for i, colour in enumerate(colours):
        atomic.write_image(folder / f"member_{i}.png", np.full((64, 64, 3), colour, np.uint8))
    return str(folder)


def test_the_wrapper_reads_its_base_against_the_cohort_and_keeps_its_points(tiny_frameset, tmp_path):
    cohort = _cohort(tmp_path / "cohort", [(200, 30, 30), (30, 30, 200), (30, 200, 30)])
    matcher = create_matcher("cohort-norm", base="color", weights=cohort, k=2, probability=False)
    base = create_matcher("color")
    target = tiny_frameset.target(tiny_frameset.episodes.target_object_id.iloc[0])
    matcher.prepare(target)
    base.prepare(target)
    images = [tiny_frameset.image(f) for f in tiny_frameset.frames.frame_id[:4]]
    cohort_scores = [r.score for r in base.match_batch(matcher.cohort)]
    stats = Impostors.of(cohort_scores, k=2, probability=False)
    assert matcher.impostors == stats
    for mine, theirs in zip(matcher.match_batch(images), base.match_batch(images)):
        assert mine.score == pytest.approx(float(stats.normalised(theirs.score)))
        sigma = 0.9 * theirs.score  # the same points pass the mapped sigma
        assert np.array_equal(mine.points_at(float(stats.normalised(sigma))), theirs.points_at(sigma))
    ranked = [r.score for r in matcher.match_batch(images)]
    assert np.argsort(ranked).tolist() == np.argsort([r.score for r in base.match_batch(images)]).tolist()


def test_the_cohorts_content_enters_the_id_and_a_bad_cohort_is_named(tmp_path):
    a = _cohort(tmp_path / "a", [(200, 30, 30)])
    b = _cohort(tmp_path / "b", [(30, 30, 200)])
    ids = {create_matcher("cohort-norm", base="color", weights=w).id for w in (a, b)}
    assert len(ids) == 2 and create_matcher("cohort-norm", base="color", weights=a).id in ids
    empty = tmp_path / "empty"
    empty.mkdir()
    matcher = create_matcher("cohort-norm", base="color", weights=str(empty))
    with pytest.raises(WeightsError, match="holds no images"):
        _ = matcher.cohort
    with pytest.raises(ConfigError, match="k must be"):
        create_matcher("cohort-norm", base="color", k=-1)


def test_the_default_cohort_is_the_shipped_core50_photos():
    matcher = create_matcher("cohort-norm", base="color")
    assert len(matcher.cohort) == 59 and matcher.cohort[0].shape == (128, 128, 3)
