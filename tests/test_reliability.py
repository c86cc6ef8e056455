"""Bad input and faults through the CLI: a clear message naming the culprit, exit code 2, nothing half-written.

The cases are listed in docs/reliability.md; frame-set validation cases live in
test_frameset.py, kill/resume and concurrent scoring in test_scoring.py.
"""

from __future__ import annotations

import errno
import json
import shutil

import cv2
import numpy as np
import pandas as pd
import pytest
import toys  # noqa: F401  (registers test-slow and test-nan-for)

from conftest import make_view
from pin_match.cli import main
from pin_match.data.frameset import FrameSet
from pin_match.data.writer import FrameSetWriter
from pin_match.scoring import RunOptions, score
from pin_match.scoring.table import ScoreTable, ScoreTableError


@pytest.fixture
def fs_copy(tiny_frameset, tmp_path):
    root = tmp_path / "fs"
    shutil.copytree(tiny_frameset.root, root)
    return root


def _run(capsys, *args) -> tuple[int, str]:
    rc = main([str(a) for a in args])
    return rc, capsys.readouterr().err


def test_corrupt_frame_fails_by_name_and_keeps_finished_episodes(fs_copy, tmp_path, capsys):
    bad = fs_copy / "frames" / "ep_val" / "0002.jpg"
    bad.write_bytes(bad.read_bytes()[:100])  # truncated JPEG
    rc, err = _run(capsys, "score", fs_copy, "--matcher", "color", "--out", tmp_path / "out", "--quiet")
    assert rc == 2 and "corrupt or unreadable image" in err and "ep_val/0002.jpg" in err
    assert [p.name for p in (tmp_path / "out").rglob("chunks/*.parquet")] == ["ep_train.parquet"]
    assert not list((tmp_path / "out").rglob("scores_*.parquet")) and not list((tmp_path / "out").rglob("*.tmp"))


def test_reference_without_alpha_fails_by_name(fs_copy, tmp_path, capsys):
    path = fs_copy / "objects_images" / "mug_a" / "mug_a_2.png"
    cv2.imwrite(str(path), np.zeros((10, 10, 3), np.uint8))
    rc, err = _run(capsys, "score", fs_copy, "--matcher", "color", "--out", tmp_path / "out", "--quiet")
    assert rc == 2 and "mug_a_2.png has no alpha channel" in err


def test_missing_reference_view_and_two_descriptions_refused_at_load(fs_copy, tmp_path, capsys):
    (fs_copy / "objects_images" / "ball_b" / "ball_b_0.png").unlink()
    rc, err = _run(capsys, "score", fs_copy, "--matcher", "color", "--out", tmp_path / "out")
    assert rc == 2 and "object 'ball_b'" in err and "2 reference views, expected 3" in err
    shutil.copy(fs_copy / "objects_images" / "ball_b" / "ball_b_1.png", fs_copy / "objects_images" / "ball_b" /
                "ball_b_0.png")
    descriptions = json.loads((fs_copy / "objects_descriptions.json").read_text())
    descriptions["mug_d"] = descriptions["mug_d"][:2]
    (fs_copy / "objects_descriptions.json").write_text(json.dumps(descriptions))
    rc, err = _run(capsys, "score", fs_copy, "--matcher", "color", "--out", tmp_path / "out")
    assert rc == 2 and "object 'mug_d'" in err and "2 descriptions, expected 3" in err


def test_newer_format_version_refused(fs_copy, tmp_path, capsys):
    manifest = json.loads((fs_copy / "frameset.json").read_text())
    manifest["version"] = 2
    (fs_copy / "frameset.json").write_text(json.dumps(manifest))
    rc, err = _run(capsys, "score", fs_copy, "--matcher", "color", "--out", tmp_path / "out")
    assert rc == 2 and "format version 2" in err and "upgrade pin_match" in err


def test_unknown_ids_refused(fs_copy, tmp_path, capsys):
    vis = pd.read_parquet(fs_copy / "visibility.parquet")
    vis.loc[0, "object_id"] = "no_such_object"
    vis.to_parquet(fs_copy / "visibility.parquet")
    rc, err = _run(capsys, "score", fs_copy, "--matcher", "color", "--out", tmp_path / "out")
    assert rc == 2 and "unknown object id 'no_such_object'" in err


def test_unknown_matcher_and_config_key_suggest_close_names(tiny_frameset, tmp_path, capsys):
    rc, err = _run(capsys, "score", tiny_frameset.root, "--matcher", "colour", "--out", tmp_path)
    assert rc == 2 and "unknown matcher 'colour'" in err and "did you mean color" in err
    rc, err = _run(capsys, "score", tiny_frameset.root, "--matcher", "color", "--cfg", "bins=4", "--out", tmp_path)
    assert rc == 2 and "no config key 'bins'" in err and "bins_h" in err
    assert not list(tmp_path.rglob("*.parquet"))


def test_non_finite_scores_name_the_matcher_and_frames(tiny_frameset, tmp_path, capsys):
    for value in ("nan", "inf"):
        rc, err = _run(capsys, "score", tiny_frameset.root, "--matcher", "test-nan-for", "--cfg", f"value={value}",
                       "--cfg", "bad_target=mug_c", "--cfg", "delay=0", "--out", tmp_path / value, "--quiet")
        assert rc == 2 and "matcher test-nan-for returned a non-finite score" in err
        assert "episode 'ep_val'" in err and "ep_val_0000" in err
        assert not list((tmp_path / value).rglob("ep_val.parquet"))  # nothing of the bad episode written


def test_score_table_with_nan_refused(tiny_frameset, tmp_path, capsys):
    table = score(tiny_frameset, "color", out=tmp_path / "s", run=RunOptions(progress=False))
    frames = table.frames.copy()
    frames.loc[3, "score"] = np.nan
    ScoreTable(frames, table.meta).write(tmp_path / "nan.parquet")
    with pytest.raises(ScoreTableError, match="frame 'ep_train_0003' has a non-finite score"):
        ScoreTable.read(tmp_path / "nan.parquet")
    rc, err = _run(capsys, "report", tmp_path / "nan.parquet", "--frameset", tiny_frameset.root)
    assert rc == 2 and "ep_train_0003" in err


def test_grayscale_and_unexpected_size_frames_are_scored(tmp_path):
    w = FrameSetWriter(tmp_path / "odd")
    view = make_view((200, 40, 40), stripe=(250, 250, 250))
    w.add_object("o1", "mug", "val", [view] * 3, ["a", "b", "c"])
    w.add_episode("e", "val", "s", "o1", [])
    for step, (h, w_) in enumerate([(517, 333), (360, 640), (200, 200)]):
        image = np.full((h, w_, 3), 80, np.uint8)
        mask = np.zeros((h, w_), np.uint16)
        image[50:146, 50:146][view[..., 3] > 0] = view[..., :3][view[..., 3] > 0]
        mask[50:146, 50:146][view[..., 3] > 0] = 1
        w.add_frame("e", step, image, mask, {1: ("o1", "target")})
    w.close()
    gray = tmp_path / "odd" / "frames" / "e" / "0000.jpg"
    cv2.imwrite(str(gray), cv2.imread(str(gray), cv2.IMREAD_GRAYSCALE))  # a grayscale file on disk
    assert cv2.imread(str(gray), cv2.IMREAD_UNCHANGED).ndim == 2
    fs = FrameSet.load(tmp_path / "odd")
    for name in ("color", "sift"):
        table = score(fs, name, out=tmp_path / "out", run=RunOptions(progress=False))
        assert len(table.frames) == 3 and np.isfinite(table.frames.score).all()
        for fid, x, y in zip(table.frames.frame_id, table.frames.points_x, table.frames.points_y):
            h, w_ = fs.image(fid).shape[:2]
            assert (np.asarray(x) < w_).all() and (np.asarray(y) < h).all()


def _fail_with(monkeypatch, err: int, where: str) -> None:
    """Make the file system refuse writes the way a read-only mount or a full disk does.

    Tests run as root in CI, and root ignores permission bits, so the refusal is injected
    at the system-call boundary pin_match uses (temporary files and exclusive creates).
    """
    import os
    import tempfile

    real_mkstemp, real_named, real_open = tempfile.mkstemp, tempfile.NamedTemporaryFile, os.open

    def mkstemp(*a, **k):
        if where in str(k.get("dir", "")):
            raise OSError(err, os.strerror(err))
        return real_mkstemp(*a, **k)

    def named(*a, **k):
        if where in str(k.get("dir", "")):
            raise OSError(err, os.strerror(err))
        return real_named(*a, **k)

    def os_open(path, flags, *a, **k):
        if where in str(path) and flags & os.O_CREAT:
            raise OSError(err, os.strerror(err))
        return real_open(path, flags, *a, **k)

    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    monkeypatch.setattr(tempfile, "NamedTemporaryFile", named)
    monkeypatch.setattr(os, "open", os_open)


def test_read_only_output_folder(tiny_frameset, tmp_path, monkeypatch, capsys):
    out = tmp_path / "readonly"
    out.mkdir()
    _fail_with(monkeypatch, errno.EROFS, str(out))
    rc, err = _run(capsys, "score", tiny_frameset.root, "--matcher", "color", "--out", out, "--quiet")
    assert rc == 2 and "cannot write into" in err and str(out) in err and "Read-only file system" in err


def test_disk_full_while_writing_the_cache_then_resume(tiny_frameset, tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    out = tmp_path / "full"
    real = pq.write_table
    calls = {"n": 0}

    def write_half_then_fail(table, where, *a, **k):
        calls["n"] += 1
        if calls["n"] == 2:  # the second episode's chunk: half the bytes, then ENOSPC
            with open(where, "wb") as fh:
                fh.write(b"PAR1" + b"\0" * 64)
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(table, where, *a, **k)

    monkeypatch.setattr(pq, "write_table", write_half_then_fail)
    with pytest.raises(OSError, match="No space left on device"):
        score(tiny_frameset, "color", out=out, run=RunOptions(progress=False))
    assert [p.name for p in out.rglob("chunks/*.parquet")] == ["ep_train.parquet"]
    assert not list(out.rglob("*.tmp")) and not list(out.rglob("*.lock"))
    monkeypatch.setattr(pq, "write_table", real)  # space freed
    resumed = score(tiny_frameset, "color", out=out, run=RunOptions(progress=False))
    reference = score(tiny_frameset, "color", out=tmp_path / "ref", run=RunOptions(progress=False))
    assert next(out.rglob("scores_all.parquet")).read_bytes() == \
        next((tmp_path / "ref").rglob("scores_all.parquet")).read_bytes()
    assert resumed.frames.equals(reference.frames)


def _retyped(path, column: str, values) -> None:
    frame = pd.read_parquet(path)
    frame[column] = values(frame[column])
    frame.to_parquet(path)


CHUNK_DAMAGES = {
    "overwritten with 3 bytes": (lambda p: p.write_bytes(b"abc"), "3 bytes"),
    "cut short": (lambda p: p.write_bytes(p.read_bytes()[:p.stat().st_size // 2]), "parquet"),
    "a column of another type": (lambda p: _retyped(p, "step", lambda s: s.astype(str)), "column step is"),
    "a column missing": (lambda p: pd.read_parquet(p).drop(columns="point_scores").to_parquet(p), "columns"),
}


@pytest.mark.parametrize("damage", list(CHUNK_DAMAGES))
def test_a_damaged_chunk_is_scored_again_and_said_so(tiny_frameset, tmp_path, capsys, damage):
    damage_file, reason = CHUNK_DAMAGES[damage]
    args = ("score", tiny_frameset.root, "--matcher", "color", "--quiet", "--out")
    assert _run(capsys, *args, tmp_path / "ref")[0] == 0
    out = tmp_path / "out"
    assert _run(capsys, *args, out)[0] == 0
    next(out.rglob("scores_all.parquet")).unlink()  # so that the chunks are read
    (train, val) = sorted(out.rglob("chunks/*.parquet"))
    damage_file(val)
    kept = train.stat().st_mtime_ns
    rc, err = _run(capsys, *args, out)
    assert rc == 0 and len(err.splitlines()) == 1, err
    assert "damaged score chunk" in err and str(val) in err and reason.lower() in err.lower()
    assert "scoring episode 'ep_val' again" in err and "Traceback" not in err
    assert next(out.rglob("scores_all.parquet")).read_bytes() == next((tmp_path / "ref").rglob(
        "scores_all.parquet")).read_bytes()
    assert train.stat().st_mtime_ns == kept  # the sound chunk was kept, not scored again
    next(out.rglob("scores_all.parquet")).unlink()
    assert _run(capsys, *args, out) == (0, "")  # the replaced chunk is sound
