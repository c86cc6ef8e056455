"""``pin-match trade``: what looking further costs, per matcher (``evaluation.flows.trade``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pin_match import outputs
from pin_match.cli.args import add_bench_config, add_run_options, add_scheduler, bench_overrides, engine_run
from pin_match.cli.evaluation import WORKERS_HELP


def _cmd_trade(a: argparse.Namespace) -> None:
    from pin_match.contract.registry import create_matcher
    from pin_match.data.frameset import FrameSet
    from pin_match.evaluation.core.evaluator import EvalContext
    from pin_match.evaluation.core.metrics import Bootstrap
    from pin_match.evaluation.core.stop import StopPolicy
    from pin_match.evaluation.core.tables import markdown_table
    from pin_match.evaluation.flows.trade import DEFAULT_WINDOWS, default_objective, trade, write_trade
    from pin_match.scoring import score_many
    from pin_match.scoring.walkups import walkup_scorer

    texts = [t.strip() for value in a.policy or [",".join(DEFAULT_WINDOWS)] for t in value.split(",") if t.strip()]
    policies = [StopPolicy.parse(t) for t in texts]
    ctx = EvalContext(FrameSet.load(a.frameset), Bootstrap(n_boot=a.bootstrap))
    configs = bench_overrides(a.cfg, a.matcher)
    built = {name: create_matcher(name, **(cfg or {})) for name, cfg in configs.items()}
    with engine_run(a) as run:
        tables = dict(zip(configs, score_many(ctx.fs, list(built.values()), out=a.out / "scores", run=run)))
        ctx.walk_ups = walkup_scorer(ctx.fs, built.values(), a.out / "scores", run)  # approach-verify's walk-ups
        objective = a.objective or default_objective(ctx.fs)
        rows = trade(ctx, tables, policies, objective=objective, tune_split=a.tune_split, read_split=a.split)
    tuned = f"sigma tuned ({objective}) on {a.tune_split} for each policy, read on {a.split}"
    csv, png = write_trade(rows, a.out, f"{a.frameset}: {tuned}")
    missing = None if a.objective else ctx.fs.navigation_missing
    print(tuned if missing is None else f"{tuned}; {objective}, the share of episodes committed to the target, as "
                                        f"SR cannot be estimated: {missing}")
    print(markdown_table(rows.set_index(["matcher", "policy"]).drop(columns=["matcher_id", "upper_bound"])))
    print(f"-> {csv}\n-> {png}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    from pin_match.evaluation.core.tuning import OBJECTIVES

    s = sub.add_parser("trade", help="SR, CE, SPL and Steps against the look-further window, per matcher",
                       description="Each matcher under each stop policy (default look:0,10,20,40 and the rest of the "
                                   "walk): sigma tuned for the policy on the train split, read on val (an approach:D "
                                   "policy's second line tuned with it); trade.csv and trade.png (docs/metrics.md, "
                                   "'Stop policies').")
    s.add_argument("frameset", type=Path, help="frame-set to score (train and val splits)")
    s.add_argument("--matcher", action="append", required=True, help="matcher to include (repeatable)")
    add_bench_config(s)
    s.add_argument("--policy", action="append", metavar="POLICY[,POLICY...]",
                   help="stop policies to compare (repeatable, comma-separated; default look:0,look:10,look:20,"
                        "look:40,look:rest)")
    s.add_argument("--objective", choices=sorted(OBJECTIVES),
                   help="what each policy's sigma maximises on the tuning split (default sr; on a frame-set without "
                        "geometry first-match, the share of episodes committed to the target)")
    s.add_argument("--tune-split", default="train", help="split sigma is tuned on (default train)")
    s.add_argument("--split", default="val", help="split read (default val)")
    s.add_argument("--bootstrap", type=int, default=1000, help="bootstrap resamples for the 95 %% CIs (default 1000)")
    s.add_argument("--out", type=Path, default=outputs.RUNS / "trade",
                   help=f"folder of trade.csv, trade.png and the score cache (default {outputs.RUNS / 'trade'})")
    add_run_options(s, workers=WORKERS_HELP)
    add_scheduler(s)
    s.set_defaults(func=_cmd_trade)
