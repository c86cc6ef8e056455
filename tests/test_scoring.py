"""Scoring is cached by config and frame-set, resumes after SIGKILL to the same bytes, shards, and shares."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import toys  # noqa: F401  (registers test-slow)

from pin_match.scoring import RunOptions, Shard, merge, score
from pin_match.scoring.schema import decode_meta, encode_meta
from pin_match.scoring.table import ScoreTable

QUIET = RunOptions(progress=False)

TESTS = Path(__file__).parent


def _cli(args: list[str], env_extra: dict | None = None) -> subprocess.Popen:
    code = "import sys, toys; from pin_match.cli import main; sys.exit(main(sys.argv[1:]))"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]),
               **(env_extra or {}))
    return subprocess.Popen([sys.executable, "-c", code, *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)


def test_table_contents(tiny_frameset, tmp_path):
    t = score(tiny_frameset, "color", out=tmp_path, run=QUIET)
    assert list(t.frames.frame_id) == sorted(tiny_frameset.frames.frame_id)
    assert t.meta["frameset_fingerprint"] == tiny_frameset.fingerprint
    assert t.meta["matcher_id"] == f"color@{t.meta['config_hash']}"
    row = t.frames.set_index("frame_id").loc["ep_val_0000"]
    assert row.score == pytest.approx(max(row.crop_scores)) and len(row.crop_scores) == 2
    assert len(row.points_x) == len(row.point_scores) > 0
    pts = t.points("ep_val_0000", 0.95 * row.score)  # the best-scoring windows lie on the target
    assert len(pts) and tiny_frameset.object_pixels("ep_val_0000", "mug_c")[
        pts[:, 1].astype(int), pts[:, 0].astype(int)].mean() > 0.5


def test_rerun_hits_the_cache_and_a_new_config_does_not(tiny_frameset, tmp_path, monkeypatch):
    log = tmp_path / "log.txt"
    monkeypatch.setenv("PIN_MATCH_TEST_LOG", str(log))
    first = score(tiny_frameset, "test-slow", overrides={"delay": 0.0}, out=tmp_path, run=QUIET)
    n = len(log.read_text().splitlines())
    again = score(tiny_frameset, "test-slow", overrides={"delay": 0.0}, out=tmp_path, run=QUIET)
    assert len(log.read_text().splitlines()) == n == 2  # no target prepared twice, nothing rescored
    assert again.frames.equals(first.frames)
    other = score(tiny_frameset, "test-slow", overrides={"delay": 0.001}, out=tmp_path, run=QUIET)
    assert other.meta["config_hash"] != first.meta["config_hash"]
    assert len(log.read_text().splitlines()) == 4


def test_read_meta_misses_a_missing_or_damaged_table_and_names_one_it_cannot_open(tmp_path, monkeypatch):
    """Issue 43.3a: a missing or damaged table (or damaged metadata) is no cache hit; a table the process may not
    read was once taken for a miss too, and rescored over: now it is an error naming the file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pin_match.scoring.cache import read_meta
    from pin_match.scoring.schema import META_KEY, encode_meta
    from pin_match.scoring.table import ScoreTableError

    good = tmp_path / "good.parquet"
    pq.write_table(pa.table({"a": [1]}).replace_schema_metadata(encode_meta({"matcher": "x"})), good)
    assert read_meta(good) == {"matcher": "x"}
    assert read_meta(tmp_path / "missing.parquet") is None
    damaged = tmp_path / "damaged.parquet"
    damaged.write_bytes(b"PAR1 damaged")
    assert read_meta(damaged) is None
    whole = good.read_bytes()
    damaged.write_bytes(whole[:-10] + whole[-8:])  # a footer pyarrow cannot parse: an OSError with no errno
    assert read_meta(damaged) is None
    pq.write_table(pa.table({"a": [1]}).replace_schema_metadata({META_KEY: b"{not json"}), damaged)
    assert read_meta(damaged) is None

    def denied(path, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(pq, "read_schema", denied)
    with pytest.raises(ScoreTableError, match=r"good\.parquet.*Permission denied"):
        read_meta(good)


def test_split_scores_only_that_split(tiny_frameset, tmp_path):
    t = score(tiny_frameset, "color", split="val", out=tmp_path, run=QUIET)
    assert set(t.frames.split) == {"val"} and len(t.frames) == 4


def test_shards_merge_to_the_unsharded_table(tiny_frameset, tmp_path):
    assert Shard.parse("1/3").select(list("abcdefg")) == ["b", "e"]
    with pytest.raises(ValueError, match="0 <= i < n"):
        Shard.parse("3/3")
    full = score(tiny_frameset, "color", out=tmp_path / "full", run=QUIET)
    parts = [score(tiny_frameset, "color", out=tmp_path / f"s{i}", shard=f"{i}/2", run=QUIET) for i in range(2)]
    assert [len(p.frames) for p in parts] == [4, 4]
    paths = sorted((tmp_path).glob("s*/*/*/scores_all_shard*.parquet"))
    merged = merge(paths, tmp_path / "merged.parquet")
    assert merged.frames.drop(columns=[]).equals(full.frames)
    with pytest.raises(Exception, match="appears in more than one part"):
        merge([paths[0], paths[0]], tmp_path / "bad.parquet")


def _table_bytes(out: Path) -> bytes:
    (path,) = out.glob("*/*/scores_all.parquet")
    return path.read_bytes()


def test_sigkill_mid_run_resumes_to_identical_bytes(tiny_frameset, tmp_path):
    args = ["score", str(tiny_frameset.root), "--matcher", "test-slow", "--cfg", "delay=0.15", "--quiet",
            "--batch-size", "2"]
    ref = _cli([*args, "--out", str(tmp_path / "ref")])
    assert ref.wait(timeout=120) == 0, ref.stderr.read().decode()

    out = tmp_path / "killed"
    proc = _cli([*args, "--out", str(out)])
    deadline = time.time() + 60
    while not list(out.glob("*/*/chunks/*.parquet")) and time.time() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert len(list(out.glob("*/*/chunks/*.parquet"))) == 1  # killed half way: one of two episodes done
    assert not list(out.glob("*/*/scores_all.parquet"))

    resumed = _cli([*args, "--out", str(out)])
    assert resumed.wait(timeout=120) == 0, resumed.stderr.read().decode()
    assert _table_bytes(out) == _table_bytes(tmp_path / "ref")
    assert not list(out.rglob("*.tmp"))


def test_two_processes_share_one_cache(tiny_frameset, tmp_path):
    args = ["score", str(tiny_frameset.root), "--matcher", "test-slow", "--cfg", "delay=0.1", "--quiet",
            "--out", str(tmp_path / "shared")]
    log = tmp_path / "log.txt"
    procs = [_cli(args, {"PIN_MATCH_TEST_LOG": str(log)}) for _ in range(2)]
    for p in procs:
        assert p.wait(timeout=120) == 0, p.stderr.read().decode()
    ref = score(tiny_frameset, "test-slow", overrides={"delay": 0.0}, out=tmp_path / "ref", run=QUIET)
    got = ScoreTable.read(next((tmp_path / "shared").glob("*/*/scores_all.parquet")))
    assert np.array_equal(got.frames.score.to_numpy(), ref.frames.score.to_numpy())
    prepared = [line.split()[-1] for line in log.read_text().splitlines()]
    assert sorted(prepared) == ["mug_a", "mug_c"]  # each episode scored by exactly one process
    assert not list((tmp_path / "shared").rglob("*.lock")) and not list((tmp_path / "shared").rglob("*.tmp"))


def test_an_empty_lock_left_by_a_kill_is_taken_over(tiny_frameset, tmp_path):
    """A process killed between creating a lock and writing its pid leaves an empty lock: not held forever."""
    ref = score(tiny_frameset, "color", out=tmp_path / "ref", run=QUIET)
    (chunks,) = [p / "chunks" for p in (tmp_path / "ref").glob("*/*")]
    for chunk in chunks.glob("*.parquet"):
        chunk.unlink()
    lock = chunks / "ep_val.lock"
    lock.touch()
    os.utime(lock, (time.time() - 60, time.time() - 60))
    (table,) = (tmp_path / "ref").glob("*/*/scores_all.parquet")
    table.unlink()
    start = time.monotonic()
    again = score(tiny_frameset, "color", out=tmp_path / "ref", run=QUIET)
    assert time.monotonic() - start < 60 and again.frames.equals(ref.frames)
    assert not lock.exists()


def test_a_cache_of_the_columns_before_view_is_scored_again_not_crashed_on(tiny_frameset, tmp_path, capsys):
    """Issue 51.4: a table and chunks written before the ``view`` column existed are no hit; every chunk counts as
    damaged (named once), and the table comes out as a fresh run's."""
    import pyarrow.parquet as pq

    ref = score(tiny_frameset, "color", out=tmp_path / "ref", run=QUIET)
    out = tmp_path / "old"
    score(tiny_frameset, "color", out=out, run=QUIET)
    (table,) = out.glob("*/*/scores_all.parquet")
    chunks = sorted(out.glob("*/*/chunks/*.parquet"))
    for path in [table, *chunks]:  # as an older version wrote them: without the column, its metadata without `columns`
        whole = pq.read_table(path)
        meta = decode_meta(whole.schema.metadata)
        older = {**whole.schema.metadata, **encode_meta({k: v for k, v in meta.items() if k != "columns"})} if meta \
            else whole.schema.metadata
        pq.write_table(whole.drop_columns(["view"]).replace_schema_metadata(older), path)
    capsys.readouterr()
    again = score(tiny_frameset, "color", out=out, run=QUIET)
    err = capsys.readouterr().err
    assert err.count("damaged score chunk") == len(chunks) == 2 and "'view'" in err and "Traceback" not in err
    assert again.frames.equals(ref.frames) and table.read_bytes() == next((tmp_path / "ref").glob(
        "*/*/scores_all.parquet")).read_bytes()
    assert (again.frames.view == -1).all()  # color names no view
