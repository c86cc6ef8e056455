"""Cohort normalisation: the statistics by hand, the wrapper keeps its base's ranking and points, the cohort's id."""

from __future__ import annotations

import numpy as np
import pytest

from pin_match import atomic
from pin_match.contract import ConfigError, WeightsError, create_matcher
from pin_match.contract.cohort import Impostors, TargetCohort, logit


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
    cohort_scores = [r.score for r in base.match_batch(list(matcher.cohort_images.values()))]
    stats = Impostors.of(cohort_scores, k=2, probability=False)
    assert matcher.cohort.impostors == stats
    notes = TargetCohort.from_notes(matcher.target_notes())  # what the score table stores for the target
    assert notes == matcher.cohort and [s for _, s in notes.members] == sorted(cohort_scores, reverse=True)
    assert notes.closest == notes.members[:2] and notes.midpoint == pytest.approx(stats.mean)
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
        _ = matcher.cohort_images
    with pytest.raises(ConfigError, match="k must be"):
        create_matcher("cohort-norm", base="color", k=-1)


def test_the_default_cohort_is_the_shipped_core50_photos():
    matcher = create_matcher("cohort-norm", base="color")
    images = matcher.cohort_images
    assert len(images) == 59 and next(iter(images.values())).shape == (128, 128, 3)
    assert "CORe50" in matcher.score_scale and "5 closest" in matcher.score_scale
    assert create_matcher("color").score_scale.startswith("raw")


def test_a_target_cohort_sorts_its_members_and_reads_back_from_its_notes():
    cohort = TargetCohort.of("/c", ["a.png", "b.png", "c.png"], [0.2, 0.9, 0.5], k=2, min_std=0.25, probability=True)
    assert cohort.members == (("b.png", 0.9), ("c.png", 0.5), ("a.png", 0.2))
    assert cohort.closest == (("b.png", 0.9), ("c.png", 0.5))
    # the midpoint is the raw score the normalised one calls 0.5: the geometric mean of the odds of 0.9 and 0.5
    assert cohort.midpoint == pytest.approx(0.75) and cohort.impostors.normalised(0.75) == pytest.approx(0.5)
    assert TargetCohort.from_notes(cohort.as_notes()) == cohort
    assert TargetCohort.from_notes({}) is None
    with pytest.raises(ValueError, match="damaged cohort notes"):
        TargetCohort.from_notes({"cohort": {"folder": "/c"}})
    with pytest.raises(ValueError, match="3 cohort names for 2 scores"):
        TargetCohort.of("/c", ["a", "b", "c"], [0.1, 0.2], k=0, min_std=0.25, probability=True)


def test_the_score_table_stores_each_targets_cohort_and_still_hits_its_cache(tiny_frameset, tmp_path):
    from pin_match.scoring import RunOptions, merge, score

    quiet = RunOptions(progress=False)
    cohort = _cohort(tmp_path / "cohort", [(200, 30, 30), (30, 30, 200), (30, 200, 30)])
    cfg = dict(base="color", weights=cohort, k=2, probability=False)
    table = score(tiny_frameset, "cohort-norm", overrides=cfg, out=tmp_path / "s", run=quiet)
    targets = sorted(set(tiny_frameset.episodes.target_object_id))
    assert sorted(table.target_notes) == targets
    matcher = create_matcher("cohort-norm", **cfg)
    for target_id in targets:
        matcher.prepare(tiny_frameset.target(target_id))
        assert TargetCohort.from_notes(table.target_notes[target_id]) == matcher.cohort
    assert table.meta["score_scale"] == matcher.score_scale
    (path,) = (tmp_path / "s").glob("*/*/scores_all.parquet")
    stamp = path.stat().st_mtime_ns
    assert score(tiny_frameset, "cohort-norm", overrides=cfg, out=tmp_path / "s", run=quiet).target_notes \
        == table.target_notes
    assert path.stat().st_mtime_ns == stamp  # the notes it gathered do not make the table look stale
    parts = [score(tiny_frameset, "cohort-norm", overrides=cfg, out=tmp_path / f"p{i}", shard=f"{i}/2", run=quiet)
             for i in range(2)]
    assert [sorted(p.target_notes) for p in parts] == [[t] for t in targets]  # one episode, one target a shard
    merged = merge(sorted(tmp_path.glob("p*/*/*/scores_all_shard*.parquet")), tmp_path / "merged.parquet")
    assert merged.target_notes == table.target_notes
    assert score(tiny_frameset, "color", out=tmp_path / "s", run=quiet).target_notes == {}


def test_variants_scored_together_prepare_their_shared_base_once(tiny_frameset, tmp_path, monkeypatch):
    from pin_match.matchers.color import ColorMatcher
    from pin_match.scoring import RunOptions, score, score_many

    quiet = RunOptions(progress=False)
    cohort = _cohort(tmp_path / "cohort", [(200, 30, 30), (30, 30, 200), (30, 200, 30)])
    configs = [dict(base="color", weights=cohort, k=k, probability=False) for k in (0, 2)]
    calls = []
    original = ColorMatcher._match_batch
    monkeypatch.setattr(ColorMatcher, "_match_batch", lambda self, images: calls.append(len(images))
                        or original(self, images))
    together = score_many(tiny_frameset, [create_matcher("cohort-norm", **c) for c in configs], out=tmp_path / "t",
                          run=quiet)
    targets = tiny_frameset.episodes.target_object_id.nunique()
    assert calls.count(3) == targets  # the three cohort images: once a target, not once a variant
    for cfg, table in zip(configs, together):
        alone = score(tiny_frameset, "cohort-norm", overrides=cfg, out=tmp_path / f"a{cfg['k']}", run=quiet)
        assert alone.frames.equals(table.frames) and alone.target_notes == table.target_notes


def test_a_cohort_folder_is_written_from_a_framesets_objects(tiny_frameset, tmp_path, capsys):
    from pin_match.cli import main
    from pin_match.data.cohort import GREY
    from pin_match.data.images import read_image

    out = tmp_path / "cohort"
    assert main(["data", "cohort", str(tiny_frameset.root), str(out), "--views", "2"]) in (0, None)
    objects = sorted(tiny_frameset.objects.object_id)
    assert sorted(p.name for p in out.glob("*.png")) == sorted(f"{o}_v{k}.png" for o in objects for k in (0, 1))
    view = tiny_frameset.target(objects[0]).views[1]
    image = read_image(out / f"{objects[0]}_v1.png")
    clear = view[..., 3] == 0
    assert clear.any() and (image[clear] == GREY).all()  # the cut-out's background is grey, its object kept
    solid = view[..., 3] == 255
    assert np.array_equal(image[solid], view[..., :3][solid])
    notice = (out / "NOTICE.md").read_text()
    assert all(f"- {o} (" in notice for o in objects) and tiny_frameset.fingerprint in notice
    matcher = create_matcher("cohort-norm", base="color", weights=str(out))
    assert len(matcher.cohort_images) == 2 * len(objects)
    assert main(["data", "cohort", str(tiny_frameset.root), str(out)]) == 2  # never over an existing folder
    assert "already exists" in capsys.readouterr().err
    assert main(["data", "cohort", str(tiny_frameset.root), str(tmp_path / "none"), "--views", "0"]) == 2
    assert "at least one view" in capsys.readouterr().err and not (tmp_path / "none").exists()


def test_notes_that_are_no_json_are_named_by_the_contract_and_the_engine(tiny_frameset, tmp_path, monkeypatch):
    from pin_match.contract import ContractError, check_matcher
    from pin_match.contract.matcher import MatcherError
    from pin_match.matchers.color import ColorMatcher
    from pin_match.scoring import RunOptions, score

    monkeypatch.setattr(ColorMatcher, "target_notes", lambda self: {"mean": float("nan")})
    with pytest.raises(ContractError, match="target_notes\\(\\) must hold JSON values"):
        check_matcher("color")
    with pytest.raises(MatcherError, match="matcher color: target_notes\\(\\) must hold JSON values"):
        score(tiny_frameset, "color", out=tmp_path, run=RunOptions(progress=False))
    assert not list(tmp_path.glob("*/*/chunks/*.parquet"))  # nothing written for the episode
