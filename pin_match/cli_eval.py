"""The evaluation half of the CLI: tune, report, similarity, bench, demo (no model needed except similarity)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pin_match.frameset import FrameSet
from pin_match.scoretable import ScoreTable


def _load_fs_for(table: ScoreTable, frameset: Path | None) -> FrameSet:
    if frameset is None:
        raise ValueError("pass --frameset: the frame-set the scores were computed on (fingerprint "
                         f"{table.meta.get('frameset_fingerprint')})")
    fs = FrameSet.load(frameset)
    if fs.fingerprint != table.meta.get("frameset_fingerprint"):
        raise ValueError(f"{frameset} has fingerprint {fs.fingerprint}, but the scores of {table.matcher_id} were "
                         f"computed on {table.meta.get('frameset_fingerprint')}")
    return fs


def _cmd_tune(a: argparse.Namespace) -> None:
    from pin_match.labels import frame_labels
    from pin_match.tuning import default_threshold_path, tune, write_thresholds

    table = ScoreTable.read(a.scores)
    fs = _load_fs_for(table, a.frameset)
    result = tune(table, frame_labels(fs), objective=a.objective, split=a.split)
    path = write_thresholds(result, a.out or default_threshold_path(table.matcher))
    print(f"{table.matcher_id}: sigma = {result['sigma']:.6g} ({a.objective} on {a.split} = "
          f"{result['objective_value']:.4g}) -> {path}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    from pin_match.tuning import DEFAULT_OBJECTIVE, OBJECTIVES

    s = sub.add_parser("tune", help="choose sigma on the train split; writes thresholds/<matcher>.json")
    s.add_argument("scores", type=Path, help="score table (parquet) from pin-match score")
    s.add_argument("--frameset", type=Path, help="the frame-set the scores came from")
    s.add_argument("--objective", default=DEFAULT_OBJECTIVE, choices=sorted(OBJECTIVES))
    s.add_argument("--split", default="train")
    s.add_argument("--out", type=Path, help="thresholds file (default thresholds/<matcher>.json)")
    s.set_defaults(func=_cmd_tune)
