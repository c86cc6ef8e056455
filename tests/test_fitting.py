"""`pin-match fit`: the fitted files come from a command, equal to the library's fit; the candidate-signal cache."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from pin_match.cli import main
from pin_match.contract.registry import create_matcher
from pin_match.fitting.fusion import fit_fusion
from pin_match.fitting.logistic import logistic_fit
from pin_match.fitting.verifier import CandidateSignals, candidate_table, fit_verifier
from pin_match.matchers.common.verifier_file import SIGNALS
from pin_match.scoring import RunOptions
from pin_match.scoring.cache import cache_dir, read_meta
from pin_match.scoring.schema import encode_meta

FAST = dict(signals=("proto", "margin", "desc", "color"), candidates=2)  # no keypoints: quick
QUIET = RunOptions(progress=False)


def run(capsys, *args) -> tuple[int, str, str]:
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    return rc, out.out, out.err


def as_read(spec: dict) -> dict:
    return json.loads(json.dumps(spec))


def test_fit_fusion_command_writes_what_the_library_fits(tiny_frameset, tmp_path, capsys):
    rc, out, _ = run(capsys, "fit", "fusion", tiny_frameset.root, "--component", "color", "--component", "sift",
                     "transform=log1p", "--out", tmp_path / "cli.json", "--cache", tmp_path / "scores", "--quiet")
    assert rc == 0 and "score with: pin-match score FRAMESET --matcher fusion --weights" in out
    spec = fit_fusion(tiny_frameset, [("color", {}, "identity"), ("sift", {}, "log1p")], tmp_path / "api.json",
                      out=tmp_path / "scores")
    assert json.loads((tmp_path / "cli.json").read_text()) == as_read(spec)
    assert [c["transform"] for c in spec["components"]] == ["identity", "log1p"]


def test_fit_fusion_command_passes_a_component_config(tiny_frameset, tmp_path, capsys):
    rc, _, _ = run(capsys, "fit", "fusion", tiny_frameset.root, "--component", "color", "bins_h=12",
                   "--component", "sift", "--out", tmp_path / "f.json", "--cache", tmp_path / "scores", "--quiet")
    spec = json.loads((tmp_path / "f.json").read_text())
    assert rc == 0 and spec["components"][0]["config"]["bins_h"] == 12
    assert spec["components"][0]["id"] == create_matcher("color", bins_h=12).id


def test_fit_fusion_command_refuses_a_bad_component_in_one_line(tiny_frameset, tmp_path, capsys):
    rc, _, err = run(capsys, "fit", "fusion", tiny_frameset.root, "--component", "transform=log1p", "--out",
                     tmp_path / "f.json")
    assert rc == 2 and "the matcher's name comes first" in err and len(err.strip().splitlines()) == 1
    rc, _, err = run(capsys, "fit", "fusion", tiny_frameset.root, "--component", "color", "transform=cube",
                     "--out", tmp_path / "f.json", "--cache", tmp_path / "scores")
    assert rc == 2 and "transform 'cube'" in err and not (tmp_path / "f.json").exists()


def test_fit_verifier_command_writes_what_the_library_fits(tiny_frameset, tmp_path, capsys):
    rc, out, _ = run(capsys, "fit", "verifier", tiny_frameset.root, "--cfg", "signals=proto,margin,desc,color",
                     "--cfg", "candidates=2", "--out", tmp_path / "cli.json", "--features", tmp_path / "feats",
                     "--quiet")
    assert rc == 0 and "--cfg signals=proto,margin,desc,color --cfg candidates=2" in out
    spec = fit_verifier([tiny_frameset], tmp_path / "api.json", overrides=FAST, out=tmp_path / "feats")
    assert json.loads((tmp_path / "cli.json").read_text()) == as_read(spec)
    # the command's signals were reused: one chunk, one table
    assert sorted(p.name for p in (tmp_path / "feats").rglob("*.parquet")) == ["candidates_train.parquet",
                                                                               "ep_train.parquet"]


def test_candidate_signals_live_in_the_score_cache_folder_and_a_bad_file_is_computed_again(tiny_frameset, tmp_path):
    matcher = create_matcher("verify", **FAST)
    first = candidate_table(tiny_frameset, matcher, out=tmp_path, run=QUIET)
    folder = cache_dir(tmp_path, CandidateSignals(FAST["signals"]).folder(matcher), tiny_frameset.fingerprint)
    path = folder / "candidates_all.parquet"
    assert read_meta(path)["signals_id"] == matcher.signals_id and read_meta(path)["signals"] == list(FAST["signals"])
    assert sorted(p.stem for p in (folder / "chunks").glob("*.parquet")) == sorted(tiny_frameset.episodes.episode_id)
    # another signal set is another table: its chunks hold other columns
    assert CandidateSignals(SIGNALS).folder(matcher) != CandidateSignals(FAST["signals"]).folder(matcher)

    path.write_bytes(b"PAR1 damaged")  # a damaged file is no hit: assembled again from the chunks
    pd.testing.assert_frame_equal(candidate_table(tiny_frameset, matcher, out=tmp_path, run=QUIET), first)
    assert read_meta(path)["signals_id"] == matcher.signals_id

    # a readable file whose metadata names another frame-set is no hit either
    forged = pa.Table.from_pandas(first.assign(x0=-1), preserve_index=False)
    meta = dict(read_meta(path), frameset_fingerprint="0" * 16)
    pq.write_table(forged.replace_schema_metadata({**forged.schema.metadata, **encode_meta(meta)}), path)
    assert (candidate_table(tiny_frameset, matcher, out=tmp_path, run=QUIET).x0 >= 0).all()

    # a damaged chunk is computed again, the table the same
    chunk = folder / "chunks" / "ep_val.parquet"
    chunk.write_bytes(b"PAR1 cut short")
    path.unlink()
    pd.testing.assert_frame_equal(candidate_table(tiny_frameset, matcher, out=tmp_path, run=QUIET), first)


def test_a_sign_constrained_fit_is_the_constrained_optimum():
    """``nonnegative`` coefficients: the unconstrained fit when it obeys, else the KKT point of the constrained loss
    (each coefficient held at 0 would only raise the loss by growing; each free one at a zero gradient)."""
    rng = np.random.default_rng(1)
    x = rng.normal(size=(300, 4)) * [1.0, 0.2, 3.0, 1.0] + [0.0, 0.5, -1.0, 2.0]
    y = (x[:, 0] - 2.0 * x[:, 1] - 0.3 * x[:, 2] + rng.normal(size=300) > 0).astype(float)
    w, l2 = np.full(300, 1 / 300), 0.5
    free = logistic_fit(x, y, w, l2)
    assert free[2] < 0 and free[3] < 0 and free[1] > 0  # columns 1 and 2 want negative weights
    assert np.array_equal(logistic_fit(x, y, w, l2, nonnegative=[0, 3]), free)  # obeyed already: unchanged
    beta = logistic_fit(x, y, w, l2, nonnegative=[1, 2])
    assert beta[2] == 0.0 and beta[3] == 0.0 and beta[1] > 0
    std = x.std(0)
    p = 1 / (1 + np.exp(-(beta[0] + x @ beta[1:])))
    gradient = x.T @ (w * (p - y)) + l2 * std**2 * beta[1:]  # of the loss logistic_fit minimises, raw coefficients
    assert abs(w @ (p - y)) < 1e-9 and abs(gradient[0]) < 1e-9 and abs(gradient[3]) < 1e-9
    assert gradient[1] > 0 and gradient[2] > 0
    # only the constrained column is held at 0; the other, left free, keeps its negative weight
    only = logistic_fit(x, y, w, l2, nonnegative=[2])
    assert only[3] == 0.0 and only[2] < 0
