"""Several matchers scored in one pass: each frame decoded once, a shared part run once, tables as if alone."""

from __future__ import annotations

import numpy as np
import pytest

from pin_match.contract import create_matcher
from pin_match.contract.shared import shared_pass
from pin_match.scoring import RunOptions, score_many, score_to_file
from pin_match.scoring.cache import cache_dir

QUIET = RunOptions(progress=False, batch_size=2)
EFFNET = "pin_match.matchers.effnet.EffnetMatcher._match_batch"


def _count(monkeypatch, target: str) -> list[int]:
    """Record the batch size of every call of ``target``, still calling it."""
    import importlib

    module, cls, name = target.rsplit(".", 2)
    owner = getattr(importlib.import_module(module), cls)
    original, calls = getattr(owner, name), []

    def counted(self, images):
        calls.append(len(images))
        return original(self, images)

    monkeypatch.setattr(owner, name, counted)
    return calls


def test_verify_and_effnet_together_run_effnet_once_per_batch_and_write_the_tables_each_writes_alone(
        tiny_frameset, tmp_path, monkeypatch):
    assert create_matcher("verify").locator.id == create_matcher("effnet").id  # verify's locate map is effnet's
    calls = _count(monkeypatch, EFFNET)
    tables = score_many(tiny_frameset, ["verify", "effnet"], out=tmp_path / "together", run=QUIET)
    together = len(calls)
    n_batches = 4  # 2 episodes x 4 frames, batches of 2
    assert together == n_batches
    decoded = _count(monkeypatch, "pin_match.data.frameset.FrameSet.image")
    alone = [score_to_file(tiny_frameset, name, out=tmp_path / "alone", run=QUIET) for name in ("verify", "effnet")]
    assert len(calls) - together == 2 * n_batches and len(decoded) == 2 * 8  # alone: twice the network, twice decoded
    for table, path in zip(tables, alone):
        with_group = cache_dir(tmp_path / "together", table.matcher_id, tiny_frameset.fingerprint) / path.name
        assert with_group.read_bytes() == path.read_bytes()


def test_a_group_decodes_each_frame_once(tiny_frameset, tmp_path, monkeypatch):
    decoded = _count(monkeypatch, "pin_match.data.frameset.FrameSet.image")
    score_many(tiny_frameset, {"color": {}, "sift": {}}, out=tmp_path, run=QUIET)
    assert len(decoded) == len(tiny_frameset.frames)


def test_a_rerun_scores_only_the_group_member_whose_table_is_missing(tiny_frameset, tmp_path, monkeypatch):
    score_to_file(tiny_frameset, "color", out=tmp_path, run=QUIET)
    calls = _count(monkeypatch, "pin_match.matchers.color.ColorMatcher._match_batch")
    tables = score_many(tiny_frameset, ["color", "sift"], out=tmp_path, run=QUIET)
    assert calls == [] and [t.matcher for t in tables] == ["color", "sift"]


def test_outside_a_pass_nothing_is_remembered_and_inside_one_another_image_is_computed(tiny_frameset):
    effnet = create_matcher("effnet")
    effnet.prepare(tiny_frameset.target(tiny_frameset.episodes.target_object_id.iloc[0]))
    image = tiny_frameset.image(tiny_frameset.frames.frame_id.iloc[0])
    first = effnet.match(image)
    assert effnet.match(image) is not first  # no pass open: computed again
    with shared_pass():
        inside = effnet.match(image)
        assert effnet.match(image) is inside  # the same buffer: remembered
        copy = effnet.match(image.copy())
        assert copy is not inside and copy.score == pytest.approx(inside.score)  # another buffer: computed
        other = tiny_frameset.image(tiny_frameset.frames.frame_id.iloc[2])
        assert not np.isclose(effnet.match(other).score, inside.score)
    assert effnet.match(image) is not inside

