"""Scoring on a Dask LocalCluster: the local path's bytes, resume across paths, a killed worker, errors."""

from __future__ import annotations

import os
import signal
import socket
import threading
import time
import warnings
from dataclasses import replace
from pathlib import Path

import pytest
import toys  # noqa: F401  (registers test-slow and test-nan-for; the workers import it too)
from distributed import Client, LocalCluster

from pin_match.cli import main
from pin_match.contract.matcher import MatcherError
from pin_match.contract.registry import create_matcher
from pin_match.scoring import RunOptions, score
from pin_match.scoring.cluster import DistributedError, MatcherSpec, _malloc_setting, connect, task_groups

QUIET = RunOptions(progress=False)


def on(client, kw: dict) -> dict:
    """The same keyword arguments of ``score``, its episodes run on ``client``'s cluster."""
    return {**kw, "run": replace(kw["run"], client=client)}


TESTS = Path(__file__).parent


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("dask") / "prepare.log"


@pytest.fixture(scope="module")
def client(log):
    """Two single-threaded worker processes that import the test matchers and log every prepare."""
    path = os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])
    env = {"PIN_MATCH_TEST_LOG": str(log), "PYTHONPATH": path}
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0", env=env) as cluster, \
            Client(cluster) as c:
        yield c


def _prepares(log: Path) -> list[tuple[int, str]]:
    """(pid, target) per prepare since the log was last cleared."""
    if not log.exists():
        return []
    return [(int(pid), target) for pid, _, target in (line.split() for line in log.read_text().splitlines())]


def _bytes(out: Path, name: str = "scores_all.parquet") -> bytes:
    (path,) = out.glob(f"*/*/{name}")
    return path.read_bytes()


def test_cluster_table_is_the_local_bytes_and_each_path_resumes_the_other(tiny_frameset, tmp_path, client, log,
                                                                           monkeypatch, capsys):
    monkeypatch.setenv("PIN_MATCH_TEST_LOG", str(log))
    kw = dict(overrides={"delay": 0.0}, run=QUIET)
    score(tiny_frameset, "test-slow", out=tmp_path / "local", **kw)
    reference = _bytes(tmp_path / "local")

    log.unlink(missing_ok=True)
    score(tiny_frameset, "test-slow", out=tmp_path / "cluster", run=RunOptions(client=client), overrides={"delay": 0.0})
    assert _bytes(tmp_path / "cluster") == reference
    assert "8/8" in capsys.readouterr().err  # the bar counts frames over the completed tasks
    assert sorted(t for _, t in _prepares(log)) == ["mug_a", "mug_c"]
    assert all(pid != os.getpid() for pid, _ in _prepares(log))

    # a local run stopped after episode ep_train (its shard wrote that chunk), finished on the cluster
    score(tiny_frameset, "test-slow", out=tmp_path / "to_cluster", shard="0/2", **kw)
    log.unlink()
    score(tiny_frameset, "test-slow", out=tmp_path / "to_cluster", **on(client, kw))
    assert _bytes(tmp_path / "to_cluster") == reference
    assert [t for _, t in _prepares(log)] == ["mug_c"]

    # and the reverse: a cluster run stopped after ep_train, finished here
    score(tiny_frameset, "test-slow", out=tmp_path / "to_local", shard="0/2", **on(client, kw))
    log.unlink()
    score(tiny_frameset, "test-slow", out=tmp_path / "to_local", **kw)
    assert _bytes(tmp_path / "to_local") == reference
    assert _prepares(log) == [(os.getpid(), "mug_c")]


def test_a_damaged_chunk_is_named_and_scored_again_on_the_cluster(tiny_frameset, tmp_path, client, capsys):
    kw = dict(overrides={"delay": 0.0}, run=QUIET)
    score(tiny_frameset, "test-slow", out=tmp_path / "local", **kw)
    reference = _bytes(tmp_path / "local")
    next((tmp_path / "local").glob("*/*/scores_all.parquet")).unlink()
    (train,) = (tmp_path / "local").glob("*/*/chunks/ep_train.parquet")
    chunk = train.with_name("ep_val.parquet")
    chunk.write_bytes(b"abc")
    kept = train.stat().st_mtime_ns
    capsys.readouterr()
    score(tiny_frameset, "test-slow", out=tmp_path / "local", **on(client, kw))
    assert _bytes(tmp_path / "local") == reference
    err = capsys.readouterr().err
    assert err.count("damaged score chunk") == 1 and "ep_val.parquet" in err and "Traceback" not in err
    assert train.stat().st_mtime_ns == kept and chunk.stat().st_size > 3  # only the damaged chunk was replaced


def test_a_matcher_error_stops_the_run_naming_the_frames_as_locally(tiny_frameset, tmp_path, client):
    kw = dict(overrides={"delay": 0.0, "bad_target": "mug_c"}, run=QUIET)
    with pytest.raises(MatcherError) as local:
        score(tiny_frameset, "test-nan-for", out=tmp_path / "local", **kw)
    with pytest.raises(MatcherError) as remote:
        score(tiny_frameset, "test-nan-for", out=tmp_path / "cluster", **on(client, kw))
    assert "non-finite score" in str(remote.value)
    assert "(episode 'ep_val', frames ep_val_0000..ep_val_0003)" in str(remote.value)
    assert str(remote.value) == str(local.value)
    assert not list((tmp_path / "cluster").glob("*/*/chunks/ep_val.parquet"))
    assert not list((tmp_path / "cluster").glob("*/*/*.parquet"))


def test_a_worker_built_unlike_the_client_refuses():
    sift = create_matcher("sift")
    with pytest.raises(DistributedError, match="install the same pin_match"):
        MatcherSpec(type(sift), sift.cfg, "sift@000000000000").build()
    assert MatcherSpec.of(sift).build().id == sift.id


def test_tasks_keep_a_target_together_and_leave_four_per_worker_thread():
    targets = {"e1": "b", "e2": "a", "e3": "b", "e4": "a", "e5": "c", "e6": "a", "e7": "b"}
    assert task_groups(list(targets), targets, threads=1) == [["e2", "e4"], ["e6", "e1"], ["e3", "e7"], ["e5"]]
    assert task_groups(list(targets), targets, threads=2) == [[e] for e in ("e2", "e4", "e6", "e1", "e3", "e7", "e5")]
    assert task_groups(["e1"], targets, threads=8) == [["e1"]]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_scheduler_is_a_clear_error_within_the_timeout(tiny_frameset, tmp_path, capsys):
    address = f"tcp://127.0.0.1:{_free_port()}"
    start = time.monotonic()
    with pytest.raises(DistributedError, match=f"cannot reach the Dask scheduler '{address}' within 2 s"):
        connect(address, timeout=2)
    assert time.monotonic() - start < 20
    assert main(["score", str(tiny_frameset.root), "--matcher", "sift", "--scheduler", address,
                 "--scheduler-timeout", "1", "--out", str(tmp_path)]) == 2
    assert "pin-match score: error: cannot reach the Dask scheduler" in capsys.readouterr().err


def test_cli_scores_on_a_local_cluster_and_on_an_address(tiny_frameset, tmp_path, client):
    args = ["score", str(tiny_frameset.root), "--matcher", "test-slow", "--cfg", "delay=0", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "here")]) == 0
    assert main([*args, "--out", str(tmp_path / "local"), "--scheduler", "local", "--workers", "1"]) == 0
    assert main([*args, "--out", str(tmp_path / "address"), "--scheduler", client.scheduler.address]) == 0
    assert _bytes(tmp_path / "local") == _bytes(tmp_path / "here") == _bytes(tmp_path / "address")


def test_local_workers_keep_glibcs_allocator_and_a_run_on_dask_defaults_says_so(tiny_frameset, tmp_path, client):
    """Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in every worker, which slows torch matchers (docs/performance.md):
    the local cluster leaves it unset, and a run on workers that have it (the fixture's) warns, naming it."""
    kw = dict(overrides={"delay": 0.0}, run=QUIET)
    with connect("local", workers=1) as local, warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        assert local.run(_malloc_setting) == {address: None for address in local.nthreads()}
        score(tiny_frameset, "test-slow", out=tmp_path / "local", **on(local, kw))
    assert not [w for w in seen if "MALLOC_TRIM_THRESHOLD_" in str(w.message)]
    with pytest.warns(UserWarning, match=r"^2 of 2 Dask workers \(e\.g\. tcp://.*\) run with "
                                         r"MALLOC_TRIM_THRESHOLD_=65536, Dask's nanny default, .* 2x slower"):
        score(tiny_frameset, "test-slow", out=tmp_path / "default", **on(client, kw))


def test_a_worker_killed_mid_episode_is_scored_again_elsewhere(tiny_frameset, tmp_path, client, log):
    """SIGKILL to the worker process that is scoring an episode: the scheduler runs it again on another."""
    client.wait_for_workers(2, timeout=120)
    log.unlink(missing_ok=True)
    result: dict = {}
    run = threading.Thread(target=lambda: result.update(table=score(
        tiny_frameset, "test-slow", overrides={"delay": 0.5}, out=tmp_path / "cluster",
        run=replace(QUIET, client=client))))
    run.start()
    deadline = time.monotonic() + 120
    while not _prepares(log) and time.monotonic() < deadline:
        time.sleep(0.02)
    victim, target = _prepares(log)[0]  # about 2 s of scoring left in that episode
    os.kill(victim, signal.SIGKILL)
    run.join(timeout=240)
    assert not run.is_alive()

    table = result["table"]
    reference = score(tiny_frameset, "test-slow", overrides={"delay": 0.0}, out=tmp_path / "local", run=QUIET)
    assert table.frames.equals(reference.frames)  # every frame once, same rows (the delay does not change scores)
    assert not table.frames.frame_id.duplicated().any()
    again = [pid for pid, t in _prepares(log) if t == target and pid != victim]
    assert len(again) == 1  # the killed episode was prepared and scored once more, by another process


def test_a_scheduler_lost_mid_run_is_a_clear_error_and_a_rerun_resumes(tiny_frameset, tmp_path, log, monkeypatch):
    """The scheduler process killed while the second episode is scored: DistributedError saying to rerun, and a
    rerun (here, in this process) keeps the first episode's chunk, scoring only the rest."""
    import subprocess
    import sys

    monkeypatch.setenv("PIN_MATCH_TEST_LOG", str(log))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])}
    scheduler_file = tmp_path / "scheduler.json"
    quiet = dict(env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", "0", "--no-dashboard", "--scheduler-file", str(scheduler_file)], **quiet)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", "--nthreads", "1", "--no-nanny",
                               "--no-dashboard", "--scheduler-file", str(scheduler_file)], **quiet)
    out, kw = tmp_path / "cache", dict(overrides={"delay": 1.0}, run=QUIET)
    result: dict = {}
    try:
        deadline = time.monotonic() + 120
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        client = connect(str(scheduler_file), timeout=60)
        client.wait_for_workers(1, timeout=120)
        log.unlink(missing_ok=True)

        def run() -> None:
            try:
                score(tiny_frameset, "test-slow", out=out, **on(client, kw))
            except Exception as exc:  # the error is the assertion below
                result["error"] = exc

        thread = threading.Thread(target=run)
        thread.start()
        while not list(out.glob("*/*/chunks/*.parquet")) and time.monotonic() < deadline:
            time.sleep(0.02)
        first = list(out.glob("*/*/chunks/*.parquet"))
        scheduler.kill()  # about 4 s into the second episode's 4 s of sleep
        thread.join(timeout=120)
        assert not thread.is_alive()
        client.close()
    finally:
        for process in (scheduler, worker):
            process.kill()
            process.wait()
    assert isinstance(result.get("error"), DistributedError), result
    assert "the scheduler lost?" in str(result["error"]) and "rerun to resume" in str(result["error"])
    # the chunks written before the loss are kept; a worker may still finish the episode it was running
    kept = {p.stem for p in out.glob("*/*/chunks/*.parquet")}
    assert len(first) == 1 and first[0].stem in kept

    log.unlink(missing_ok=True)
    table = score(tiny_frameset, "test-slow", out=out, **kw)
    episode_targets = dict(zip(tiny_frameset.episodes.episode_id, tiny_frameset.episodes.target_object_id))
    rest = [target for episode, target in episode_targets.items() if episode not in kept]
    assert [t for _, t in _prepares(log)] == rest  # only the episode without a chunk was scored again
    reference = score(tiny_frameset, "test-slow", overrides={"delay": 0.0}, out=tmp_path / "local", run=QUIET)
    assert table.frames.equals(reference.frames)


def test_candidate_signals_and_a_matcher_group_on_the_cluster_are_the_local_ones(tiny_frameset, tmp_path, client):
    import pandas as pd

    from pin_match.fitting.verifier import candidate_table
    from pin_match.scoring import score_many

    verify = create_matcher("verify", candidates=2)
    local = candidate_table(tiny_frameset, verify, out=tmp_path / "local", run=QUIET)
    on_dask = candidate_table(tiny_frameset, verify, out=tmp_path / "cluster", run=RunOptions(client=client))
    # the same rows; a network's float sums may differ in the last bits with the thread count a worker runs
    assert len(local) >= len(tiny_frameset.frames)
    pd.testing.assert_frame_equal(on_dask, local, check_exact=False, rtol=1e-4, atol=1e-5)
    group = ["color", "sift"]
    score_many(tiny_frameset, group, out=tmp_path / "group_local", run=QUIET)
    score_many(tiny_frameset, group, out=tmp_path / "group_dask", run=RunOptions(client=client))
    for name in group:
        (a,) = (tmp_path / "group_local").glob(f"{name}@*/*/scores_all.parquet")
        (b,) = (tmp_path / "group_dask").glob(f"{name}@*/*/scores_all.parquet")
        assert a.read_bytes() == b.read_bytes()
