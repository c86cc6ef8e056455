"""The page-writing half of the CLI: ``inspect`` (a frame-set's own page) and ``compare`` (two matchers, paired)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pin_match import outputs
from pin_match.data.frameset import FrameSet


def _cmd_inspect(a: argparse.Namespace) -> None:
    from pin_match.evaluation.frameset_page import write_frameset_page

    fs = FrameSet.load(a.frameset)
    out = a.out or outputs.RUNS / "inspect" / fs.fingerprint
    print(write_frameset_page(fs, out, per_role=a.per_role, seed=a.seed))


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
