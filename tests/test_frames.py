"""Matchers scored in one pass share one batch of frames: RGB once, a part computed once under its key (id, device,
target), a copy for each asker, and every table the bytes it has when scored alone."""

from __future__ import annotations

import dataclasses
import importlib

import numpy as np
import pytest

from pin_match.contract import Frames, Matcher, MatcherConfig, MatchResult, Target, create_matcher, register_matcher
from pin_match.contract.weights import WeightsSpec
from pin_match.data.frameset import FrameSet
from pin_match.scoring import RunOptions, score_many, score_to_file
from pin_match.scoring.cache import cache_dir

QUIET = RunOptions(progress=False, batch_size=2)
THREADS = RunOptions(progress=False, batch_size=2, workers=2)  # a parallel_frames matcher on two threads a batch
EFFNET = "pin_match.matchers.effnet.EffnetMatcher._match_batch"
N_BATCHES = 4  # the tiny frame-set: 2 episodes (2 targets) x 4 frames, batches of 2


def _count(monkeypatch, target: str) -> list[int]:
    """Record the batch size of every call of ``target`` (a dotted path), still calling it."""
    module, cls, name = target.rsplit(".", 2)
    return _count_on(monkeypatch, getattr(importlib.import_module(module), cls), name)


def _count_on(monkeypatch, owner: type, name: str) -> list[int]:
    original, calls = getattr(owner, name), []

    def counted(self, images):
        calls.append(len(images))
        return original(self, images)

    monkeypatch.setattr(owner, name, counted)
    return calls


def _same_bytes(together: list, out, fs: FrameSet, alone: list) -> None:
    for table, path in zip(together, alone):
        assert (cache_dir(out, table.matcher_id, fs.fingerprint) / path.name).read_bytes() == path.read_bytes()


class Probe(Matcher):
    """A score that says the device and the target it was computed for: results lent under a wrong key are wrong."""

    name = "test-probe"

    def _prepare(self, target: Target) -> None:
        self.level = float(target.views[0][..., :3].mean())

    def _match_batch(self, images: list[np.ndarray]) -> list[MatchResult]:
        on_cpu = self.cfg.device == "cpu"
        return [MatchResult(score=self.level + float(im.mean()) / 1000 + (0.0 if on_cpu else 0.5), points=[[1, 2]])
                for im in images]


def test_verify_and_effnet_together_run_effnet_once_per_batch_and_write_the_tables_each_writes_alone(
        tiny_frameset, tmp_path, monkeypatch):
    assert create_matcher("verify").locator.id == create_matcher("effnet").id  # verify's locate map is effnet's
    assert tiny_frameset.episodes.target_object_id.nunique() == 2  # two targets in the one pass
    calls = _count(monkeypatch, EFFNET)
    effnet_class = type(create_matcher("effnet"))
    prepared, prepare = [], effnet_class._prepare
    monkeypatch.setattr(effnet_class, "_prepare", lambda self, target: prepared.append(target.object_id)
                        or prepare(self, target))
    tables = score_many(tiny_frameset, ["verify", "effnet"], out=tmp_path / "together", run=QUIET)
    together = len(calls)
    assert together == N_BATCHES
    assert sorted(prepared) == ["mug_a", "mug_c"]  # issue 60.4: effnet's reference encodings once a target, not twice
    decoded = _count(monkeypatch, "pin_match.data.frameset.FrameSet.image")
    alone = [score_to_file(tiny_frameset, name, out=tmp_path / "alone", run=QUIET) for name in ("verify", "effnet")]
    assert len(calls) - together == 2 * N_BATCHES and len(decoded) == 2 * 8  # alone: twice the network, twice decoded
    _same_bytes(tables, tmp_path / "together", tiny_frameset, alone)


@pytest.mark.parametrize("kind", ["rgba", "grey"])
def test_rgba_and_grey_frames_are_made_rgb_once_and_a_shared_part_still_runs_once(tiny_frameset, tmp_path,
                                                                                   monkeypatch, kind):
    """The cascade asks for its parts (``color``, which spreads a batch over two threads, and ``sift``) while both
    are scored beside it: each runs once a frame, and every table is its bytes alone."""
    original = FrameSet.image

    def converted(self, frame_id):
        rgb = original(self, frame_id)
        if kind == "grey":
            return rgb.mean(axis=2).astype(np.uint8)
        return np.concatenate([rgb, np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=2)

    monkeypatch.setattr(FrameSet, "image", converted)
    color = _count(monkeypatch, "pin_match.matchers.color.ColorMatcher._match_batch")
    sift = _count(monkeypatch, "pin_match.matchers.sift.SiftMatcher._match_batch")
    cascade = create_matcher("parts-cascade", patch="color", keypoints="sift")
    tables = score_many(tiny_frameset, [cascade, "color", "sift"], out=tmp_path / "together", run=THREADS)
    n_frames = len(tiny_frameset.frames)
    assert sum(color) == n_frames and sum(sift) == n_frames and max(color) == 1  # once a frame; color on 2 threads
    alone = [score_to_file(tiny_frameset, m, out=tmp_path / "alone", run=THREADS)
             for m in (create_matcher("parts-cascade", patch="color", keypoints="sift"), "color", "sift")]
    _same_bytes(tables, tmp_path / "together", tiny_frameset, alone)


def test_a_part_on_another_device_is_computed_again_and_its_table_is_its_own(tiny_frameset, tmp_path, own_registry):
    """``test-probe`` on ``meta`` has the id of the cascade's ``test-probe`` part on ``cpu`` but not its numbers: lent
    the part's results, its table would differ from the one it writes alone."""
    register_matcher("test-probe")(Probe)
    cascade = create_matcher("parts-cascade", patch="test-probe", keypoints="sift")
    meta = Probe(MatcherConfig(device="meta"))
    assert meta.id == cascade.patch.id and cascade.patch.cfg.device == "cpu"
    tables = score_many(tiny_frameset, [cascade, meta], out=tmp_path / "together", run=QUIET)
    alone = [score_to_file(tiny_frameset, m, out=tmp_path / "alone", run=QUIET)
             for m in (create_matcher("parts-cascade", patch="test-probe", keypoints="sift"),
                       Probe(MatcherConfig(device="meta")))]
    _same_bytes(tables, tmp_path / "together", tiny_frameset, alone)  # lent the cpu part's numbers, it would differ


def test_a_batch_lends_a_matchers_results_only_under_its_id_device_and_target(tiny_frameset, monkeypatch):
    calls = _count_on(monkeypatch, Probe, "_match_batch")
    images = [tiny_frameset.image(f) for f in tiny_frameset.frames.frame_id[:2]]
    mug_a = tiny_frameset.target("mug_a")
    renamed = dataclasses.replace(tiny_frameset.target("mug_c"), object_id="mug_a")  # another target, one name
    cpu, twin, meta, other = Probe(), Probe(), Probe(MatcherConfig(device="meta")), Probe()
    for matcher, target in ((cpu, mug_a), (twin, mug_a), (meta, mug_a), (other, renamed)):
        matcher.prepare(target)
    assert cpu.id == meta.id == other.id  # the device and the target are not in the id, but in the key
    frames = Frames(images)
    lent = {m: [r.score for r in frames.results(m)] for m in (cpu, twin, meta, other)}
    assert calls == [2, 2, 2]  # the twin was lent the cpu matcher's results; the others computed their own
    assert lent[twin] == lent[cpu] and lent[meta] == pytest.approx([s + 0.5 for s in lent[cpu]])
    assert lent[other] != lent[cpu]
    for matcher in (cpu, meta, other):
        assert [r.score for r in matcher.match_batch(images)] == lent[matcher]  # what it computes alone


def test_each_asker_gets_its_own_copy_and_rgba_or_grey_frames_are_converted_once(tiny_frameset):
    probe = Probe()
    probe.prepare(tiny_frameset.target("mug_a"))
    rgb = tiny_frameset.image(tiny_frameset.frames.frame_id.iloc[0])
    frames = Frames([rgb, np.dstack([rgb, np.full(rgb.shape[:2], 7, np.uint8)]), rgb[..., 0]])
    assert frames[0] is rgb and np.array_equal(frames[1], rgb) and frames[1].flags.c_contiguous
    assert frames[2].shape == rgb.shape and np.array_equal(frames[2][..., 2], rgb[..., 0])
    first = frames.results(probe)
    first[0].score, first[0].points[:] = -1.0, 0.0
    second = frames.results(probe)
    assert second[0] is not first[0] and second[0].score > 0 and second[0].points.tolist() == [[1.0, 2.0]]
    own = frames.for_one()
    assert own is not frames and own == frames and own.results(probe)[0].score == second[0].score  # the same loans


def test_an_id_is_hashed_once_per_config(tmp_path, monkeypatch):
    hashed = []
    original = WeightsSpec.identity
    monkeypatch.setattr(WeightsSpec, "identity", lambda self, override: hashed.append(override)
                        or original(self, override))
    folder = tmp_path / "cohort"
    folder.mkdir()
    (folder / "one.png").write_bytes(b"not read, hashed")
    matcher = create_matcher("cohort-norm", base="color", weights=str(folder))
    first = matcher.id
    assert matcher.id == first and matcher.config_hash == first.split("@")[1] and len(hashed) == 1
    matcher.cfg.weights = None  # a config changed after construction: hashed again, another id
    assert matcher.id != first and len(hashed) == 2


def test_a_group_decodes_each_frame_once(tiny_frameset, tmp_path, monkeypatch):
    decoded = _count(monkeypatch, "pin_match.data.frameset.FrameSet.image")
    score_many(tiny_frameset, {"color": {}, "sift": {}}, out=tmp_path, run=QUIET)
    assert len(decoded) == len(tiny_frameset.frames)


def test_a_rerun_scores_only_the_group_member_whose_table_is_missing(tiny_frameset, tmp_path, monkeypatch):
    score_to_file(tiny_frameset, "color", out=tmp_path, run=QUIET)
    calls = _count(monkeypatch, "pin_match.matchers.color.ColorMatcher._match_batch")
    tables = score_many(tiny_frameset, ["color", "sift"], out=tmp_path, run=QUIET)
    assert calls == [] and [t.matcher for t in tables] == ["color", "sift"]
