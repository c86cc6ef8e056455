"""--scheduler on every command that runs through the engine: bench, carry, demo, features, as score (issue 53.2)."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest

from pin_match.cli import main
from pin_match.errors import PinMatchError


class Stop(PinMatchError):
    """Raised by the stand-in library functions once they have seen their run options."""


@pytest.fixture
def cluster(monkeypatch) -> list:
    """``scoring.cluster.connect`` replaced by one that records its arguments and hands out a stand-in client."""
    from pin_match.scoring import cluster as cluster_module

    opened: list = []

    @contextlib.contextmanager
    def connect(address, *, workers, timeout):
        opened.append(dict(address=address, workers=workers, timeout=timeout, closed=False))
        yield f"client of {address}"
        opened[-1]["closed"] = True

    monkeypatch.setattr(cluster_module, "connect", connect)
    return opened


def _seen_run(monkeypatch, module, name: str) -> list:
    """Replace ``module.name`` by a function that records the ``run`` it is given and stops the command."""
    runs: list = []

    def record(*args, run, **kwargs):
        runs.append(run)
        raise Stop(f"{name} saw the run options")

    monkeypatch.setattr(module, name, record)
    return runs


@pytest.mark.parametrize("command", ["bench", "carry", "demo", "features"])
def test_the_scheduler_reaches_the_scoring_engine(command, tiny_frameset, tmp_path, monkeypatch, cluster, capsys):
    from pin_match import scoring
    from pin_match.evaluation.flows import bench, demo
    from pin_match.training import features

    fs = str(tiny_frameset.root)
    module, name, args = dict(
        bench=(bench, "bench", ["bench", fs, "--matcher", "color", "--out", str(tmp_path / "b")]),
        carry=(scoring, "score_many", ["carry", fs, fs, "--matcher", "color", "--cache", str(tmp_path / "s")]),
        demo=(demo, "demo", ["demo", "--out", str(tmp_path / "d"), "--no-lookalikes"]),
        features=(features, "build_features", ["features", fs, "--backbone", "dino", "--out", str(tmp_path / "f")]),
    )[command]
    runs = _seen_run(monkeypatch, module, name)
    assert main([*args, "--quiet", "--workers", "1"]) == 2
    assert runs[-1].client is None and runs[-1].workers == 1 and not runs[-1].progress and cluster == []
    assert main([*args, "--workers", "3", "--scheduler", "tcp://node01:8786", "--scheduler-timeout", "5"]) == 2
    assert runs[-1].client == "client of tcp://node01:8786" and runs[-1].workers == 3
    assert cluster == [dict(address="tcp://node01:8786", workers=3, timeout=5.0, closed=False)]
    assert f"pin-match {command}: error: {name} saw the run options" in capsys.readouterr().err


def test_bench_on_a_local_cluster_writes_the_local_tables(tiny_frameset, tmp_path):
    pytest.importorskip("distributed")
    args = ["bench", str(tiny_frameset.root), "--matcher", "color", "--matcher", "sift", "--workers", "1", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "here")]) == 0
    assert main([*args, "--out", str(tmp_path / "local"), "--scheduler", "local"]) == 0
    here = sorted(p.relative_to(tmp_path / "here") for p in (tmp_path / "here").rglob("scores_*.parquet"))
    assert len(here) == 2
    for table in here:
        assert (tmp_path / "local" / table).read_bytes() == (tmp_path / "here" / table).read_bytes(), table
    assert Path(tmp_path / "local" / "table.csv").read_text() == Path(tmp_path / "here" / "table.csv").read_text()
