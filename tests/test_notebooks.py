"""The analysis notebooks (issue 7) run headlessly on a small synthetic bench and render figures.

Executed copies go to pytest's tmp folder only: the notebooks in git keep no outputs.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from pin_match.data.synth import SynthSize, generate
from pin_match.evaluation import Bootstrap, EvalContext
from pin_match.evaluation.core.analysis import AnalysisError, load_bench
from pin_match.evaluation.flows.bench import bench
from pin_match.scoring import RunOptions

REPO = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((REPO / "notebooks").glob("[0-9][0-9]_*.ipynb"))
NAMES = ["01_benchmark_overview", "02_threshold_tuning", "03_similarity", "04_error_gallery", "05_training",
         "06_report_galleries"]
MATCHERS = ["sift", "color"]


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory):
    """A demo-shaped folder: run/frameset (synthetic) plus bench's scores, thresholds and reports."""
    run = tmp_path_factory.mktemp("nb") / "run"
    size = SynthSize(seed=1, episodes=4, objects_per_family=4, frames_per_episode=8)
    fs = generate(run / "frameset", size, workers=1)
    bench(EvalContext(fs, Bootstrap(n_boot=50)), MATCHERS, run, run=RunOptions(workers=1, progress=False))
    return run


def test_every_notebook_is_shipped_without_outputs():
    assert [p.stem for p in NOTEBOOKS] == NAMES
    for path in NOTEBOOKS:
        nb = json.loads(path.read_text(encoding="utf-8"))
        code = [c for c in nb["cells"] if c["cell_type"] == "code"]
        assert "parameters" in code[0].get("metadata", {}).get("tags", []), path.name
        for cell in code:
            assert cell["outputs"] == [] and cell["execution_count"] is None, path.name


def test_the_readme_installs_what_opens_the_notebooks_and_counts_them_right():
    """Issue 43.5: the README said ``jupyter lab`` but no extra installed Jupyter, and counted five notebooks."""
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    readme = (REPO / "notebooks" / "README.md").read_text(encoding="utf-8")
    extras = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    assert "pip install -e '.[notebooks]'" in readme and "notebooks" in extras
    installed = {re.split(r"[<>=!~\[; ]", requirement)[0].lower() for requirement in extras["notebooks"]}
    assert {"jupyterlab", "ipykernel", "nbconvert"} <= installed  # jupyter lab, the kernel, the headless run
    words = ["no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten"]
    assert f"executes all {words[len(NAMES)]} " in " ".join(readme.split())
    assert all(f"`{name}`" in readme for name in NAMES)


def test_load_bench(bench_run):
    run = load_bench(bench_run)
    assert sorted(run.matchers) == sorted(MATCHERS)
    for name in MATCHERS:
        assert run.sigmas[name] == run.reports[name]["sigma"] == run.tuned[name]["sigma"]
        assert run.tables[name].meta["frameset_fingerprint"] == run.frameset.fingerprint
        val = run.scored(name, "val")
        assert set(val.split) == {"val"} and len(run.scored(name)) == len(run.frameset.frames)  # the walks' frames
        assert run.frameset.approach_views.empty  # a synthetic set's walk-ups are rendered on demand, not stored
    # the synthetic set has geometry: the navigation estimate comes first, in the paper's order
    assert list(run.table().columns[:12]) == ["sigma", "sigma from", "SR", "SPL", "CE", "D2G", "Steps", "Not found",
                                              "%Match", "TM", "CM", "NM"]
    assert set(run.table()["sigma from"]) == {"tuned: first-match on train"}


def test_load_bench_errors(bench_run, tmp_path):
    with pytest.raises(AnalysisError, match="no reports"):
        load_bench(tmp_path, bench_run / "frameset")
    other = generate(tmp_path / "other", SynthSize(seed=2, episodes=2, objects_per_family=2, frames_per_episode=2),
                     workers=1)
    with pytest.raises(AnalysisError, match="reports frame-set"):
        load_bench(bench_run, other)
    copy = tmp_path / "copy"
    shutil.copytree(bench_run / "reports", copy / "reports")
    with pytest.raises(AnalysisError, match="no score table"):
        load_bench(copy, bench_run / "frameset")


@pytest.fixture(scope="module")
def trained_head(bench_run, tmp_path_factory):
    """A head trained for 2 epochs on the bench frame-set with the tiny random ViT (05_training reads it)."""
    from tiny_weights import save_tiny_timm_vit

    from pin_match.training import Backbone, TrainConfig, train

    root = tmp_path_factory.mktemp("training")
    backbone_cfg = dict(model_name="test_vit", img_size=64, weights=str(save_tiny_timm_vit(root / "vit")))
    train(bench_run / "frameset", root / "head", backbone=Backbone("dino", backbone_cfg), features=root / "features",
          cfg=TrainConfig(epochs=2, hidden=16, threads=1), progress=False)
    return root


@pytest.mark.parametrize("name", NAMES)
def test_notebook_runs(name, bench_run, tmp_path, monkeypatch, request):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    monkeypatch.setenv("PIN_MATCH_RUN_DIR", str(bench_run))
    monkeypatch.delenv("PIN_MATCH_FRAMESET", raising=False)  # default: RUN_DIR/frameset
    monkeypatch.setenv("MPLBACKEND", "Agg")  # the notebooks switch to the inline backend themselves
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    if name == "05_training":
        training = request.getfixturevalue("trained_head")
        monkeypatch.setenv("PIN_MATCH_HEAD", str(training / "head"))
        monkeypatch.setenv("PIN_MATCH_FEATURES", str(training / "features"))
    nb = nbformat.read(REPO / "notebooks" / f"{name}.ipynb", as_version=4)
    client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                     resources={"metadata": {"path": str(REPO)}})
    try:
        client.execute()  # raises CellExecutionError on any cell error
    finally:
        nbformat.write(nb, tmp_path / f"{name}.executed.ipynb")  # for inspection, never into notebooks/
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    assert any("image/png" in o.get("data", {}) for o in outputs), f"{name} rendered no figure"
