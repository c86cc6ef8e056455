"""The benchmark runner's quiet-machine rule: load averages recorded, --json refused on a busy machine."""

from __future__ import annotations

import json
import sys
import types
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ is a folder of the repository, not installed

from benchmarks import __main__ as runner  # noqa: E402
from benchmarks.loadavg import busy_figures, refusal  # noqa: E402


def test_refusal_names_each_busy_benchmark_and_its_load():
    loads = {"bench_a": {"before": 0.4, "after": 1.9}, "bench_b": {"before": 2.1, "after": 0.3},
             "bench_c": {"before": 1.5, "after": 1.5}}
    assert busy_figures(loads) == {"bench_b": 2.1}  # 1.5 itself is quiet; the load after does not count
    message = refusal(loads, noisy=False)
    assert "bench_b (load 2.10)" in message and "bench_a" not in message and "bench_c" not in message
    assert "--noisy" in message
    assert refusal(loads, noisy=True) is None
    assert refusal({"bench_a": {"before": 1.49}}, noisy=False) is None


@pytest.fixture
def fake_runs(monkeypatch):
    """Two benchmarks that return a figure each, and load averages read in turn from a list."""
    loads = []
    monkeypatch.setattr(runner, "load_1min", lambda: loads.pop(0))
    monkeypatch.setattr(runner, "machine", lambda: {"cpus": 2})
    monkeypatch.setattr(runner.importlib, "import_module",
                        lambda name: types.SimpleNamespace(run=lambda quick: {"figure": name}))
    return loads


def test_json_is_refused_after_a_busy_benchmark_and_written_with_noisy(fake_runs, tmp_path, capsys):
    out = tmp_path / "results.json"
    args = ["--only", "bench_sweep", "bench_synth", "--json", str(out)]
    fake_runs[:] = [0.2, 0.2, 0.5, 3.0, 0.4]  # now; sweep before/after; synth before/after
    assert runner.main(args) == 2
    assert not out.exists()
    captured = capsys.readouterr()
    assert "bench_synth (load 3.00)" in captured.err and "bench_sweep" not in captured.err
    assert "(load average before: 3.00)" in captured.out

    fake_runs[:] = [0.2, 0.5, 3.0, 0.4]  # --noisy skips the first look
    assert runner.main([*args, "--noisy"]) == 0
    written = json.loads(out.read_text())
    assert written["noisy"] is True
    assert written["bench_synth"] == {"figure": "benchmarks.bench_synth", "load_1min": {"before": 3.0, "after": 0.4}}
    assert written["load_1min"]["bench_sweep"] == {"before": 0.2, "after": 0.5}


def test_a_quiet_machine_writes_json(fake_runs, tmp_path):
    out = tmp_path / "results.json"
    fake_runs[:] = [0.1, 0.1, 0.2]
    assert runner.main(["--only", "bench_sweep", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["noisy"] is False


def test_a_cached_frameset_is_built_once_then_loaded(tmp_path):
    from benchmarks.framesets import _write_procedural, cached

    builds = []

    def build(root):
        builds.append(root)
        return _write_procedural(root, n_frames=2, frames_per_episode=2, seed=0)

    first = cached(tmp_path / "p", build)
    again = cached(tmp_path / "p", build)
    assert builds == [tmp_path / "p"] and len(again.frames) == 2
    assert again.fingerprint == first.fingerprint
    # one no longer current (a synthetic set of another definition of its houses) is built again, not read stale
    cached(tmp_path / "p", build, current=lambda fs: fs.fingerprint != first.fingerprint)
    assert builds == [tmp_path / "p"] * 2


def test_a_synthetic_set_is_current_only_at_its_sizes_and_this_install_s_houses():
    from types import SimpleNamespace

    from benchmarks.framesets import made_as
    from pin_match.data.synth import SynthSize
    from pin_match.data.synth.generator import definition
    from pin_match.data.synth.scans import ScanFolder

    size = SynthSize(episodes=6, rooms=2)
    made = dict(seed=0, episodes=6, objects_per_family=5, frames_per_episode=1000, walk="explore", rooms=2,
                definition=definition(ScanFolder.open()))
    assert made_as(SimpleNamespace(manifest={"provenance": made}), size)
    assert not made_as(SimpleNamespace(manifest={"provenance": made | {"rooms": 3}}), size)
    assert not made_as(SimpleNamespace(manifest={"provenance": made | {"definition": "0123"}}), size)


def test_fastest_interleaves_the_sides_and_keeps_each_ones_fastest_run(monkeypatch):
    from benchmarks import timing

    clock, calls = [0.0], []
    monkeypatch.setattr(timing, "time", types.SimpleNamespace(perf_counter=lambda: clock[0],
                                                              process_time=lambda: clock[0] / 2))
    durations = {"a": [3.0, 1.0, 2.0], "b": [1.0, 5.0, 4.0]}

    def side(name):
        def run():
            calls.append(name)
            clock[0] += durations[name][sum(c == name for c in calls) - 1]
        return run

    best = timing.fastest({"a": side("a"), "b": side("b")}, repeats=3)
    assert calls == ["a", "b"] * 3
    assert best == {"a": timing.Timing(1.0, 0.5), "b": timing.Timing(1.0, 0.5)}


def test_the_bare_network_side_runs_on_exactly_the_matchers_input(monkeypatch):
    """bench_effnet's bare side and ``matcher.match`` feed the trunk the same batches, whatever the preprocessing."""
    import torch

    from benchmarks.bench_effnet import network_inputs
    from pin_match import Target, create_matcher

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    matcher = create_matcher("effnet", layer="blocks.3", img_size=64)
    view = np.full((48, 48, 4), 255, np.uint8)
    matcher.prepare(Target("box", "toy", (view, view, view), ("a", "b", "c")))
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (640, 360, 3), dtype=np.uint8) for _ in range(2)]
    bb, fed = matcher.backbone, []
    feature_map = bb.feature_map
    monkeypatch.setattr(bb, "feature_map", lambda x: fed.append(x.clone()) or feature_map(x))
    for image in images:
        matcher.match(image)
    bare = network_inputs(matcher, images)
    assert len(fed) == len(bare) == 2 and fed[0].shape[0] == 2  # one frame's two PIN crops per pass
    for matched, prepared in zip(fed, bare):
        assert torch.equal(matched, prepared)
