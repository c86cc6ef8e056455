"""A third-party matcher shipped as its own installed distribution, found through its entry point.

The distribution is real as far as Python is concerned: a package plus a ``*.dist-info``
folder with METADATA and entry_points.txt on the path, which is what ``pip install``
leaves behind. Its matcher is decorated with one name and advertised under another, the
case that used to rename the class for everyone (and so change every cache key).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

PLUGIN = textwrap.dedent('''
    """Gray-level histogram intersection with the target's pixels: a weight-free toy matcher."""
    from dataclasses import dataclass

    import numpy as np

    from pin_match import CropConfig, CropMatcher, MatchResult, Target, register_matcher


    @dataclass
    class GrayHistConfig(CropConfig):
        bins: int = 16


    @register_matcher("toy-gray-hist")
    class GrayHist(CropMatcher):
        Config = GrayHistConfig
        default_sigma = 0.5

        def _hist(self, gray):
            h = np.histogram(gray, bins=self.cfg.bins, range=(0, 256))[0].astype(np.float64)
            return h / max(h.sum(), 1.0)

        def _prepare(self, target: Target) -> None:
            view = target.views[0]
            self._ref = self._hist(view[..., :3].mean(-1)[view[..., 3] > 0])

        def _match_crops(self, crops):
            return [MatchResult(score=float(np.minimum(self._hist(c.mean(-1)), self._ref).sum()),
                                points=[[c.shape[1] / 2, c.shape[0] / 2]]) for c in crops]
''')


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("site")
    (root / "toy_plugin.py").write_text(PLUGIN)
    info = root / "toy_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[pin_match.matchers]\ngrayhist = toy_plugin:GrayHist\n")
    (info / "RECORD").write_text("")
    return root


def _cli(args: list[str], plugin_path: Path, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(plugin_path), str(Path(__file__).parents[1])]))
    return subprocess.run([sys.executable, "-m", "pin_match", *args], env=env, cwd=cwd, capture_output=True,
                          text=True, timeout=300)


def test_entry_point_name_never_renames_the_class(plugin_path, monkeypatch):
    from pin_match.contract.registry import create_matcher, list_matchers
    from pin_match.contract.testing import check_matcher

    monkeypatch.syspath_prepend(str(plugin_path))
    assert "grayhist" in list_matchers("gray*")
    by_decorator = create_matcher("toy-gray-hist") if "toy-gray-hist" in list_matchers() else None
    by_entry_point = create_matcher("grayhist")
    before = by_entry_point.id
    assert before.startswith("toy-gray-hist@")  # the class keeps the name it was registered under
    again = create_matcher("toy-gray-hist")
    assert again.id == by_entry_point.id == before
    if by_decorator is not None:
        assert by_decorator.id == before
    assert check_matcher("grayhist")["PIN 640x360"] > 0


def test_plugin_scores_tunes_and_reports_through_the_cli(plugin_path, tiny_frameset, tmp_path):
    listed = _cli(["list", "gray*"], plugin_path, tmp_path)
    assert listed.returncode == 0 and "grayhist" in listed.stdout, listed.stderr
    scored = _cli(["score", str(tiny_frameset.root), "--matcher", "grayhist", "--out", "scores", "--quiet"],
                  plugin_path, tmp_path)
    assert scored.returncode == 0, scored.stderr
    cache = [p for p in (tmp_path / "scores").glob("toy-gray-hist@*/*") if p.is_dir()]
    assert len(cache) == 1, list((tmp_path / "scores").rglob("*"))
    tuned = _cli(["tune", str(cache[0]), "--frameset", str(tiny_frameset.root), "--out", "grayhist.json"],
                 plugin_path, tmp_path)
    assert tuned.returncode == 0, tuned.stderr
    sigma = json.loads((tmp_path / "grayhist.json").read_text())
    assert sigma["matcher_id"].startswith("toy-gray-hist@")
    reported = _cli(["report", str(cache[0]), "--frameset", str(tiny_frameset.root), "--thresholds", "grayhist.json",
                     "--bootstrap", "10", "--out", "report"], plugin_path, tmp_path)
    assert reported.returncode == 0, reported.stderr
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())
    assert metrics["matcher_id"] == sigma["matcher_id"]
