"""The page-writing half of the CLI: ``inspect`` (a frame-set's own page) and ``compare`` (two matchers, paired)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pin_match import outputs
from pin_match.cli.args import add_bench_config, bench_overrides
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError


class CompareUsageError(PinMatchError, ValueError):
    """Arguments of ``compare`` that argparse cannot check alone."""


def _cmd_inspect(a: argparse.Namespace) -> None:
    from pin_match.evaluation.pages.frameset_page import write_frameset_page

    fs = FrameSet.load(a.frameset)
    out = a.out or outputs.RUNS / "inspect" / fs.fingerprint
    print(write_frameset_page(fs, out, per_role=a.per_role, seed=a.seed))


def _cmd_compare(a: argparse.Namespace) -> None:
    from pin_match.evaluation.core.evaluator import EvalContext
    from pin_match.evaluation.core.metrics import Bootstrap
    from pin_match.evaluation.core.sigma import resolve_sigma
    from pin_match.evaluation.core.tables import markdown_table
    from pin_match.evaluation.flows.compare import AtSigma, compare
    from pin_match.scoring.cache import find_score_table
    from pin_match.scoring.table import ScoreTable

    if len(a.matcher) != 2 or len(a.threshold or [None, None]) != 2:
        raise CompareUsageError("name two matchers (--matcher A --matcher B) and, if any, two --threshold values")
    overrides = bench_overrides(a.cfg, a.matcher, "compared")
    fs = FrameSet.load(a.frameset)
    tables = [ScoreTable.read(find_score_table(a.cache, fs, name, overrides[name] or None)) for name in a.matcher]
    sides = [AtSigma(t, resolve_sigma(t.matcher_id, t.meta.get("default_sigma"), s, a.thresholds))
             for t, s in zip(tables, a.threshold or [None, None])]
    out = a.out or outputs.RUNS / "compare" / f"{a.matcher[0]}_vs_{a.matcher[1]}" / str(a.split)
    done = compare(*sides, EvalContext(fs, Bootstrap(n_boot=a.bootstrap)), out, split=a.split)
    print(markdown_table(done.paired.round(3)))
    print(f"-> {done.folder.page}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("inspect", help="an HTML page of a frame-set: every reference, sample frames per role, counts",
                       description="Write an offline HTML page showing every object's reference views (failed "
                                   "cut-outs flagged), a sample of frames per role with mask outlines, and the "
                                   "counts per split and category; prints its path.")
    s.add_argument("frameset", type=Path, help="frame-set folder")
    s.add_argument("--out", type=Path, help=f"folder of the page (default {outputs.RUNS}/inspect/<fingerprint>)")
    s.add_argument("--per-role", type=int, default=8, help="sample frames shown per role (default 8)")
    s.add_argument("--seed", type=int, default=0, help="seed of the frame sample (default 0)")
    s.set_defaults(func=_cmd_inspect)

    s = sub.add_parser("compare", help="two matchers on the same frames: paired differences, McNemar, disagreements",
                       description="Paired comparison of two scored matchers on one split (docs/metrics.md, "
                                   "'Paired comparison'); writes compare.csv, compare.md and compare.html.")
    s.add_argument("--frameset", type=Path, required=True, help="the frame-set both were scored on")
    s.add_argument("--matcher", action="append", required=True, help="matcher A, then matcher B (twice)")
    add_bench_config(s)
    g = s.add_mutually_exclusive_group()
    g.add_argument("--threshold", type=float, action="append", metavar="SIGMA",
                   help="sigma of A, then of B (twice); default: each matcher's default sigma")
    g.add_argument("--thresholds", metavar="paper", help="'paper' for the paper's sigmas")
    s.add_argument("--split", default="val", help="split compared (default val; 'all' for every frame)")
    s.add_argument("--cache", type=Path, default=outputs.SCORES, help=f"the score cache (default {outputs.SCORES})")
    s.add_argument("--bootstrap", type=int, default=1000, help="bootstrap resamples (default 1000)")
    s.add_argument("--out", type=Path, help=f"folder (default {outputs.RUNS}/compare/<A>_vs_<B>/<split>)")
    s.set_defaults(func=_cmd_compare)
