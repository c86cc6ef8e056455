"""Every command, given bad input that argparse accepts, ends in one line on stderr and exit 2: never a traceback."""

from __future__ import annotations

import argparse

import pytest

from pin_match.cli import build_parser, main


def bad_arguments(fs: str, tmp: str) -> list[list[str]]:
    missing = f"{tmp}/missing"
    return [
        ["synth", f"{tmp}/s1", "--episodes", "1"],
        ["synth", f"{tmp}/s2", "--objects-per-family", "1"],
        ["synth", f"{tmp}/s3", "--frames-per-episode", "0"],
        ["import", missing, "--objects", missing, "--out", f"{tmp}/imported"],
        ["data", "build", "recolour", fs],  # an existing frame-set, without --overwrite
        ["data", "build", "core50", fs],
        ["data", "build", "core50", f"{tmp}/c", "--variant", "drawn"],
        ["data", "build", "grocery", f"{tmp}/g"],  # no --src: prepare first
        ["data", "build", "no-such-source", f"{tmp}/n"],
        ["data", "prepare", "core50", missing, missing, "--out", f"{tmp}/src"],
        ["data", "prepare", "core50", missing, "--out", f"{tmp}/src"],  # two inputs needed
        ["data", "prepare", "recolour", missing, "--out", f"{tmp}/src"],
        ["data", "prepare", "gso", missing, "--out", f"{tmp}/src"],  # not a checkout of the scans' repository
        ["data", "cohort", missing, f"{tmp}/cohort"],  # no frame-set there
        ["data", "cohort", fs, fs],  # an existing folder, without --overwrite
        ["score", missing, "--matcher", "color"],
        ["score", fs, "--matcher", "no-such-matcher"],
        ["score", fs, "--matcher", "color", "--shard", "3/3"],
        ["score", fs, "--matcher", "color", "--shard", "one-of-two"],
        ["score", fs, "--matcher", "color", "--cfg", "crops"],
        ["score", fs, "--matcher", "color", "--cfg", "no_such_key=1"],
        ["score", fs, "--matcher", "color", "--cfg", "crops=tiles"],
        ["score", fs, "--matcher", "sift", "--weights", missing],
        ["merge", f"{missing}.parquet", "--out", f"{tmp}/merged.parquet"],
        ["tune", "--frameset", missing, "--matcher", "color"],
        ["tune", "--frameset", fs, "--matcher", "color", "--cache", missing],
        ["tune", "--frameset", fs],
        ["report", "--frameset", fs, "--matcher", "color", "--cache", missing],
        ["report", f"{missing}.parquet", "--frameset", fs],
        ["similarity", missing, "--matcher", "color"],
        ["similarity", fs, "--matcher", "color", "--split", "no-such-split"],
        ["bench", missing, "--matcher", "color"],
        ["bench", fs, "--matcher", "no-such-matcher"],
        ["bench", fs, "--matcher", "color", "--cfg", "stride=8"],  # bench's --cfg names its matcher
        ["bench", fs, "--matcher", "color", "--cfg", "sift:ratio=0.7", "--out", f"{tmp}/b"],
        ["bench", fs, "--matcher", "color", "--cfg", "color:no_such_key=1", "--out", f"{tmp}/b"],
        ["demo", "--matcher", "no-such-matcher", "--out", f"{tmp}/demo"],
        ["inspect", missing],
        ["compare", "--frameset", fs, "--matcher", "color"],  # one matcher: nothing to compare
        ["compare", "--frameset", fs, "--matcher", "color", "--matcher", "sift", "--cache", missing],
        ["compare", "--frameset", fs, "--matcher", "color", "--matcher", "sift", "--cfg", "effnet:img_size=224"],
        ["features", fs, "--backbone", "color"],
        ["features", missing, "--backbone", "effnet"],
        ["train", fs, "--out", f"{tmp}/head", "--holdout", "2"],
        ["train", missing, "--out", f"{tmp}/head"],
        ["list", "no-such-matcher"],
        ["fit", "fusion", missing, "--component", "color", "--out", f"{tmp}/fusion.json"],
        ["fit", "fusion", fs, "--component", "no-such-matcher", "--out", f"{tmp}/fusion.json"],
        ["fit", "verifier", missing, "--out", f"{tmp}/verify.json"],
        ["fit", "verifier-report", "--train", missing, "--eval", fs],
        ["carry", fs, "--matcher", "color"],  # one frame-set: nothing to leave out
        ["carry", fs, missing, "--matcher", "color", "--cache", f"{tmp}/scores"],
        ["carry", fs, f"{fs}:no-such-split", "--matcher", "color", "--cache", f"{tmp}/scores"],
        ["carry", fs, fs, "--matcher", "color", "--vary", "stride"],  # no values
        ["carry", fs, fs, "--matcher", "color", "--vary", "no_such_key=1,2"],
        ["trade", missing, "--matcher", "color", "--out", f"{tmp}/t"],
        ["trade", fs, "--matcher", "color", "--policy", "look:far", "--out", f"{tmp}/t"],
        ["score", fs, "--matcher", "color", "--matcher", "color"],
    ]


def _leaf_commands(parser: argparse.ArgumentParser) -> set[tuple[str, ...]]:
    """Every command as the words that name it: ``("score",)``, ``("data", "build")``, ``("fit", "fusion")``."""
    groups = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return {(name, *rest) for g in groups for name, sub in g.choices.items()
            for rest in (_leaf_commands(sub) or {()})}


def test_the_bad_arguments_cover_every_command(tiny_frameset, tmp_path):
    commands = _leaf_commands(build_parser()) - {("data", "list")}  # its only option is a flag: nothing to get wrong
    assert {("data", "build"), ("fit", "verifier-report"), ("list",)} <= commands
    cases = bad_arguments(str(tiny_frameset.root), str(tmp_path))
    covered = {c for c in commands if any(tuple(args[:len(c)]) == c for args in cases)}
    assert covered == commands, f"commands without a bad-arguments case: {sorted(commands - covered)}"


@pytest.mark.parametrize("index", range(len(bad_arguments("FS", "TMP"))),
                         ids=[" ".join(a) for a in bad_arguments("FS", "TMP")])
def test_bad_input_gives_one_line_and_exit_2(index, tiny_frameset, tmp_path, capsys):
    args = bad_arguments(str(tiny_frameset.root), str(tmp_path))[index]
    code = main(args)  # an exception other than PinMatchError would escape here and fail the test
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert err.startswith(f"pin-match {args[0]}: error: "), err
