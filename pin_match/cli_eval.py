"""The evaluation half of the CLI: tune, report, similarity, bench, demo (no model needed except similarity)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pin_match.frameset import FrameSet
from pin_match.scoretable import ScoreTable


def _load_fs_for(table: ScoreTable, frameset: Path) -> FrameSet:
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


def _cmd_report(a: argparse.Namespace) -> None:
    from pin_match.report import report

    table = ScoreTable.read(a.scores)
    fs = _load_fs_for(table, a.frameset)
    out = a.out or Path(a.scores).parent / "report"
    result = report(table, fs, out, sigma=a.threshold, thresholds=a.thresholds, split=a.split, n_boot=a.bootstrap)
    m = result["metrics"]
    print(f"{table.matcher_id} on {result['split']} at sigma {result['sigma']:.6g} ({result['sigma_source']}): "
          f"%Match {_fmt(m.get('match_pct'))}  TM {_fmt(m.get('tm_pct'))}  CM {_fmt(m.get('cm_pct'))}  "
          f"NM {_fmt(m.get('nm_pct'))} -> {out}")


def _fmt(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f}"


def _cmd_similarity(a: argparse.Namespace) -> None:
    from pin_match.registry import create_matcher, parse_overrides
    from pin_match.similarity import similarity, write_similarity

    fs = FrameSet.load(a.frameset)
    overrides = parse_overrides(a.cfg)
    if a.weights:
        overrides["weights"] = a.weights
    matcher = create_matcher(a.matcher, **overrides)
    table, matrix = similarity(fs, matcher, split=a.split)
    out = a.out or Path("pin_match_runs") / "similarity" / matcher.id
    write_similarity(table, matrix, out, title=f"{matcher.id}, {a.split} frontal references")
    print(table.to_string(float_format=lambda v: f"{v:.3f}"))
    print(f"-> {out}")


def _cmd_bench(a: argparse.Namespace) -> None:
    from pin_match.bench import bench
    from pin_match.report import markdown_table

    joint, _ = bench(a.frameset, a.matcher, a.out, objective=a.objective, batch_size=a.batch_size,
                     workers=a.workers, progress=not a.quiet)
    print(markdown_table(joint))
    print(f"-> {a.out}")


def _cmd_demo(a: argparse.Namespace) -> None:
    from pin_match.bench import OFFLINE_MATCHERS, demo
    from pin_match.report import markdown_table

    joint, out = demo(a.out, a.matcher or OFFLINE_MATCHERS, seed=a.seed, workers=a.workers, progress=not a.quiet)
    print("\nPIN detection metrics on the synthetic val split (sigma tuned on train):\n")
    print(markdown_table(joint))
    print(f"\nreports, plots, thresholds and score tables: {out}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    from pin_match.bench import DEMO_OUT
    from pin_match.tuning import DEFAULT_OBJECTIVE, OBJECTIVES

    s = sub.add_parser("tune", help="choose sigma on the train split; writes thresholds/<matcher>.json")
    s.add_argument("scores", type=Path, help="score table (parquet) from pin-match score")
    s.add_argument("--frameset", type=Path, required=True, help="the frame-set the scores came from")
    s.add_argument("--objective", default=DEFAULT_OBJECTIVE, choices=sorted(OBJECTIVES))
    s.add_argument("--split", default="train")
    s.add_argument("--out", type=Path, help="thresholds file (default thresholds/<matcher>.json)")
    s.set_defaults(func=_cmd_tune)

    s = sub.add_parser("report", help="metrics, tables and plots of a score table at one sigma")
    s.add_argument("scores", type=Path)
    s.add_argument("--frameset", type=Path, required=True)
    g = s.add_mutually_exclusive_group()
    g.add_argument("--threshold", type=float)
    g.add_argument("--thresholds", type=Path, help="a tuned thresholds file or thresholds/paper.json")
    s.add_argument("--split", default="val")
    s.add_argument("--bootstrap", type=int, default=1000, help="bootstrap resamples for the CIs")
    s.add_argument("--out", type=Path)
    s.set_defaults(func=_cmd_report)

    s = sub.add_parser("similarity", help="intra/inter-category similarity of frontal references")
    s.add_argument("frameset", type=Path)
    s.add_argument("--matcher", required=True)
    s.add_argument("--cfg", action="append", metavar="KEY=VALUE")
    s.add_argument("--weights")
    s.add_argument("--split", default="val")
    s.add_argument("--out", type=Path)
    s.set_defaults(func=_cmd_similarity)

    for name, helptext in (("bench", "score, tune on train and report on val for several matchers"),
                           ("demo", "the whole job on the synthetic default frame-set (generated if absent)")):
        s = sub.add_parser(name, help=helptext)
        if name == "bench":
            s.add_argument("frameset", type=Path)
            s.add_argument("--matcher", action="append", required=True)
            s.add_argument("--out", type=Path, default=Path("pin_match_runs") / "bench")
            s.add_argument("--objective", default=DEFAULT_OBJECTIVE, choices=sorted(OBJECTIVES))
            s.add_argument("--batch-size", type=int, default=8)
        else:
            s.add_argument("--matcher", action="append")
            s.add_argument("--out", type=Path, default=DEMO_OUT)
            s.add_argument("--seed", type=int, default=0)
        s.add_argument("--workers", type=int)
        s.add_argument("--quiet", action="store_true")
        s.set_defaults(func=_cmd_bench if name == "bench" else _cmd_demo)
