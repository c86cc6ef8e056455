"""The evaluation half of the CLI: tune, report, similarity, bench, carry, demo.

``tune`` and ``report`` take a score table by path or find it in the score cache from
``--frameset`` and ``--matcher`` (the same ``--cfg`` / ``--weights`` as ``score``); ``bench``
configures each of its matchers with ``--cfg MATCHER:KEY=VALUE``. Every command prints the
sigma it used and where it came from.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from pin_match import outputs
from pin_match.cli.args import (
    UsageError,
    add_bench_config,
    add_matcher_config,
    add_run_options,
    add_scheduler,
    bench_overrides,
    engine_run,
    matcher_overrides,
    policy_argument,
    policy_of,
)
from pin_match.data.frameset import FrameSet
from pin_match.scoring.cache import cache_dir
from pin_match.scoring.table import ScoreTable

if TYPE_CHECKING:
    from pin_match.contract.matcher import Matcher
    from pin_match.evaluation.core.stop import StopPolicy
    from pin_match.evaluation.flows.carry import ScoredSet

WORKERS_HELP = ("worker processes/threads (default: up to 2 for scoring, all cores for rendering); with "
                "--scheduler local, the Dask worker processes that score")


def _table(a: argparse.Namespace, fs: FrameSet) -> ScoreTable:
    """The table named by path, else the one the score cache holds for --matcher on --frameset."""
    from pin_match.scoring.cache import find_score_table

    if len(a.scores) > 1:
        raise UsageError(f"{len(a.scores)} score tables given ({', '.join(map(str, a.scores[:3]))}...): a shell glob "
                         "matched several; name one, or use --matcher NAME with --frameset")
    if bool(a.scores) == (a.matcher is not None):
        raise UsageError("name the score table: its path, or --matcher NAME (found in --cache for --frameset)")
    if a.scores:
        return ScoreTable.read(a.scores[0])
    return ScoreTable.read(find_score_table(a.cache, fs, a.matcher, matcher_overrides(a)))


def _walk_ups(a: argparse.Namespace, fs: FrameSet):
    """An approach-verify policy's walk-ups on a synthetic set, rendered and scored by the --matcher named (none for
    a table given by path: the command then says an approach-verify policy needs the matcher)."""
    from pin_match.contract.registry import create_matcher
    from pin_match.scoring.walkups import walkup_scorer

    return None if a.matcher is None else walkup_scorer(fs, [create_matcher(a.matcher, **matcher_overrides(a))],
                                                         a.cache)


def _cmd_tune(a: argparse.Namespace) -> None:
    from pin_match.evaluation.core.evaluator import EvalContext
    from pin_match.evaluation.core.tuning import default_threshold_path, tune, write_thresholds

    fs = FrameSet.load(a.frameset)
    table = _table(a, fs)
    if a.policy is None:
        result = tune(table, fs, objective=a.objective, split=a.split)
    else:
        from pin_match.evaluation.core.policies import tune_policy

        ctx = EvalContext(fs, walk_ups=_walk_ups(a, fs))
        result = tune_policy(table, ctx, policy_of(a), objective=a.objective, split=a.split)
    path = write_thresholds(result, a.out or default_threshold_path(table.matcher))
    policy = f", stop policy {result['policy']}" if "policy" in result else ""
    print(f"{table.matcher_id}: sigma = {result['sigma']:.6g} (tuned: {a.objective} on {a.split} = "
          f"{result['objective_value']:.4g}{policy}) -> {path}")


def _cmd_report(a: argparse.Namespace) -> None:
    from pin_match.evaluation.core.evaluator import EvalContext
    from pin_match.evaluation.core.metrics import Bootstrap
    from pin_match.evaluation.flows.report import report

    fs = FrameSet.load(a.frameset)
    table = _table(a, fs)
    out = a.out or cache_dir(outputs.REPORTS, table.matcher_id, fs.fingerprint) / str(a.split)
    result = report(table, EvalContext(fs, Bootstrap(n_boot=a.bootstrap), _walk_ups(a, fs)), out, sigma=a.threshold,
                    thresholds=a.thresholds, split=a.split, policy=policy_of(a))
    m = result["metrics"]
    print(f"{table.matcher_id} on {result['split']} at sigma {result['sigma']:.6g} ({result['sigma_detail']}): "
          f"%Match {_fmt(m.get('match_pct'))}  TM {_fmt(m.get('tm_pct'))}  CM {_fmt(m.get('cm_pct'))}  "
          f"NM {_fmt(m.get('nm_pct'))} -> {out}")


def _fmt(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f}"


def _cmd_similarity(a: argparse.Namespace) -> None:
    from pin_match.contract.registry import create_matcher
    from pin_match.evaluation.core.similarity import similarity, write_similarity

    fs = FrameSet.load(a.frameset)
    matcher = create_matcher(a.matcher, **matcher_overrides(a))
    table, matrix = similarity(fs, matcher, split=a.split)
    out = a.out or outputs.SIMILARITY / matcher.id
    write_similarity(table, matrix, out, title=f"{matcher.id}, {a.split} frontal references")
    print(table.to_string(float_format=lambda v: f"{v:.3f}"))
    print(f"-> {out}")


def _cmd_bench(a: argparse.Namespace) -> None:
    from pin_match.evaluation.core.tables import markdown_table
    from pin_match.evaluation.flows.bench import SigmaRule, bench
    from pin_match.evaluation.flows.compare import compare_bench
    from pin_match.evaluation.flows.index_page import SetResults, write_index

    overrides = bench_overrides(a.cfg, a.matcher)
    with engine_run(a) as run:
        done = bench(a.frameset, overrides, a.out, sigma=SigmaRule(a.sigma_from, a.objective, policy_of(a)), run=run)
    print(markdown_table(done.joint))
    comparisons = compare_bench(done.run)
    if comparisons:
        print("paired comparisons:", *(c.folder.page for c in comparisons), sep="\n  ")
    print(f"-> {write_index(a.out, [SetResults('bench', f'{a.frameset}, val split', done, comparisons)])}")


def _cmd_demo(a: argparse.Namespace) -> None:
    from dataclasses import replace

    from pin_match.evaluation.core.tables import markdown_table
    from pin_match.evaluation.flows.bench import Stopwatch
    from pin_match.evaluation.flows.demo import DEMO_SETS, LOOKALIKES, SCANNED, demo

    picked = {SCANNED.name: a.matcher, LOOKALIKES.name: a.lookalike_matcher}
    sets = [replace(s, matchers=tuple(picked[s.name] or s.matchers)) for s in DEMO_SETS
            if not (a.no_lookalikes and s is LOOKALIKES)]
    watch = Stopwatch()
    with engine_run(a) as run:
        results = demo(a.out, sets, seed=a.seed, run=run, watch=watch, tune=a.tune)
    for r in results:
        print(f"\n{r.sigma_note}")
        print(f"PIN metrics on {r.caption}; {r.bench.caption}\n")
        print(markdown_table(r.bench.joint))
    print(f"\nreports, plots, thresholds and score tables: {a.out}")
    print(f"\nwhere the time went (wall seconds; scoring reuses cached tables):\n{watch.breakdown()}")
    print(f"\nthe story, every table and a link to every page: {Path(a.out) / 'index.html'}")


def _cmd_carry(a: argparse.Namespace) -> None:
    from pin_match import atomic
    from pin_match.contract.registry import create_matcher
    from pin_match.evaluation.core.evaluator import EvalContext
    from pin_match.evaluation.core.metrics import Bootstrap
    from pin_match.evaluation.flows.carry import ScoredSet
    from pin_match.scoring import score_many

    if len(a.framesets) < 2:
        raise UsageError(f"carry needs at least two frame-sets (one is left out at a time), got {a.framesets}")
    configs = {label: create_matcher(a.matcher, **cfg) for label, cfg in _variants(a).items()}
    policies = _policies(a)
    contexts = {}  # every frame-set loaded and its split checked before anything is scored
    for item in a.framesets:
        path, _, split = item.partition(":")
        ctx = EvalContext(FrameSet.load(path), Bootstrap(n_boot=a.bootstrap))
        splits = set(ctx.fs.episodes.split)
        reading = split or ("val" if "val" in splits else None)
        ctx.fs.split(reading)  # a split the set lacks is named here
        contexts[item] = (ctx, "train" if "train" in splits else None, reading)
    scored: dict[str, dict[str, ScoredSet]] = {label: {} for label in configs}
    with engine_run(a) as run:
        for item, (ctx, tuning, reading) in contexts.items():  # the variants in one pass: a shared part runs once
            tables = score_many(ctx.fs, list(configs.values()), out=a.cache, run=run)
            for label, table in zip(configs, tables):
                places = ctx.placements(table, reading) if ctx.fs.navigation_missing is None else None
                scored[label][item] = ScoredSet(tuning=ctx.scored(table, tuning), reading=ctx.scored(table, reading),
                                                clusters=ctx.clusters, placements=places)
    variants = {_variant_label(c, p, len(configs), a.policy): (c, p) for c in configs for p in policies}
    report = _carry_report(a, configs, scored, variants)
    if a.json:
        atomic.write_json(a.json, report)
        print(f"-> {a.json}")


def _carry_report(a: argparse.Namespace, configs: dict[str, Matcher], scored: dict[str, dict[str, ScoredSet]],
                  variants: dict[str, tuple[str, StopPolicy]]) -> dict:
    """Print each variant's leave-one-set-out rows, then (several variants) the variant chosen without each set;
    return what ``--json`` writes."""
    import pandas as pd

    from pin_match.evaluation.core.metrics import Bootstrap
    from pin_match.evaluation.core.stop import FIRST_MATCH
    from pin_match.evaluation.flows.carry import chosen_and_carried, headline, leave_one_out

    boot = Bootstrap(n_boot=a.bootstrap)
    walks = any(s.placements is not None for sets in scored.values() for s in sets.values())
    columns = ["set", "auroc_same", "sigma", "match", "cm", "cm_low", "cm_high", "first_precision", "first_success",
               "own_sigma", "own_match", "own_cm", "own_first_precision", "own_first_success", "first_gap",
               "success_gap", *(["sr", "ce", "own_sr", "own_ce"] if walks else []),
               *(["commit_target", "commit_lookalike", "looked", "own_commit_target", "commit_gap"]
                 if any(p != FIRST_MATCH for _, p in variants.values()) else [])]
    report: dict = dict(matcher=a.matcher, variants={label: configs[c].id for label, (c, _) in variants.items()},
                        policies={label: str(p) for label, (_, p) in variants.items()}, rows={})
    with pd.option_context("display.width", 250, "display.max_colwidth", 60):
        for label, (config, policy) in variants.items():
            rows = leave_one_out(scored[config], boot, policy)
            report["rows"][label] = dict(headline(rows), rows=rows.to_dict("records"))
            print(f"{configs[config].id} ({label}): sigma chosen on every other set, read on the set (worst first)\n"
                  + rows[columns].round(3).to_string(index=False) + "\n")
        if len(variants) > 1:
            rows = chosen_and_carried({label: scored[c] for label, (c, _) in variants.items()}, boot,
                                      {label: p for label, (_, p) in variants.items()})
            report["chosen"] = dict(headline(rows), rows=rows.to_dict("records"))
            varied = " and ".join([*([a.vary.split("=")[0]] if a.vary else []), *(["stop policy"] if a.policy else [])])
            print(f"{varied} chosen on the other sets alone, then sigma on them, read on the set (worst first)\n"
                  + rows[["variant", *columns]].round(3).to_string(index=False))
    return report


def _policies(a: argparse.Namespace) -> list[StopPolicy]:
    """The stop policies of ``--policy`` (each value a comma-separated list; default PIN's rule), in order."""
    from pin_match.evaluation.core.stop import FIRST_MATCH, StopPolicy

    texts = [t.strip() for value in a.policy or [] for t in value.split(",") if t.strip()]
    policies = list(dict.fromkeys(StopPolicy.parse(t) for t in texts)) or [FIRST_MATCH]
    if a.policy and len(texts) != len(policies):
        raise UsageError(f"--policy {', '.join(texts)}: a policy is named twice")
    return policies


def _variant_label(config: str, policy: StopPolicy, n_configs: int, named_policies: list[str] | None) -> str:
    """A variant's label: its config's (``--vary``), its stop policy's (``--policy``), or both."""
    if not named_policies:
        return config
    return str(policy) if n_configs == 1 else f"{config} {policy}"


def _variants(a: argparse.Namespace) -> dict[str, dict]:
    """The matcher's configs by label: one (``--cfg``), or one per value of ``--vary KEY=V1,V2,...`` on top of it."""
    base = matcher_overrides(a)
    if not a.vary:
        return {"as configured": base}
    key, sep, values = a.vary.partition("=")
    labels = [v.strip() for v in values.split(",") if v.strip()]
    if not sep or not key.strip() or len(labels) < 2 or len(set(labels)) < len(labels):
        raise UsageError(f"--vary {a.vary!r}: expected KEY=V1,V2,... with at least two different values")
    return {f"{key.strip()}={v}": {**base, key.strip(): v} for v in labels}


def _table_arguments(s: argparse.ArgumentParser) -> None:
    s.add_argument("scores", type=Path, nargs="*",
                   help="score table (parquet, or its cache folder) printed by `pin-match score`; or use --matcher")
    s.add_argument("--frameset", type=Path, required=True, help="the frame-set the scores were computed on")
    s.add_argument("--matcher", help="find the table of this matcher for --frameset in --cache instead of a path")
    add_matcher_config(s, "with --matcher: as given to `pin-match score`,")
    s.add_argument("--cache", type=Path, default=outputs.SCORES,
                   help=f"with --matcher: the score cache (the --out of `pin-match score`; default {outputs.SCORES})")


def add_commands(sub: argparse._SubParsersAction) -> None:
    for add in (_add_tune, _add_report, _add_similarity, _add_bench, _add_carry, _add_demo):
        add(sub)


def _objective_argument(s: argparse.ArgumentParser) -> None:
    from pin_match.evaluation.core.tuning import DEFAULT_OBJECTIVE, OBJECTIVES

    s.add_argument("--objective", default=DEFAULT_OBJECTIVE, choices=sorted(OBJECTIVES),
                   help=f"what the chosen sigma maximises (default {DEFAULT_OBJECTIVE}; see docs/metrics.md)")


def _add_tune(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("tune", help="choose sigma on one split (train by default); writes thresholds/<matcher>.json",
                       description="Choose a matcher's sigma on one split of the frame-set it was scored on.")
    _table_arguments(s)
    _objective_argument(s)
    s.add_argument("--split", default="train",
                   help="split to tune on (default train; tuning on the split you report is optimistic)")
    s.add_argument("--out", type=Path, help="thresholds file to write (default thresholds/<matcher>.json)")
    policy_argument(s, "tune for this stop policy")
    s.set_defaults(func=_cmd_tune)


def _add_report(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("report", help="metrics, tables and plots of a score table at one sigma",
                       description="Metrics, tables and plots of one split at one sigma. Sigma: --threshold, else "
                                   "--thresholds, else the matcher's default; every output says which.")
    _table_arguments(s)
    g = s.add_mutually_exclusive_group()
    g.add_argument("--threshold", type=float, metavar="SIGMA", help="report at this sigma")
    g.add_argument("--thresholds", metavar="FILE|paper",
                   help="a thresholds file written by `pin-match tune`, or 'paper' for the paper's sigmas")
    s.add_argument("--split", default="val", help="split to report (default val; 'all' for every frame)")
    s.add_argument("--bootstrap", type=int, default=1000, help="bootstrap resamples for the 95 %% CIs (default 1000)")
    s.add_argument("--out", type=Path,
                   help=f"report folder (default {outputs.REPORTS}/<matcher@hash>/<fingerprint>/<split>)")
    policy_argument(s, "read the navigation estimate and what the agent commits to under this stop policy")
    s.set_defaults(func=_cmd_report)


def _add_similarity(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("similarity", help="intra/inter-category similarity of frontal references")
    s.add_argument("frameset", type=Path, help="frame-set whose objects are compared")
    s.add_argument("--matcher", required=True, help="registered matcher whose embedding is used")
    add_matcher_config(s)
    s.add_argument("--split", default="val", help="objects of this split (default val; 'all' for every object)")
    s.add_argument("--out", type=Path, help=f"output folder (default {outputs.SIMILARITY}/<matcher@hash>)")
    s.set_defaults(func=_cmd_similarity)


def _add_bench(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("bench", help="score, choose sigma (tuned on train) and report val for several matchers")
    s.add_argument("frameset", type=Path, help="frame-set to score (needs a val split)")
    s.add_argument("--matcher", action="append", required=True, help="matcher to include (repeatable)")
    s.add_argument("--out", type=Path, default=outputs.BENCH,
                   help=f"folder of scores, thresholds, reports, table.md/.tex/.csv (default {outputs.BENCH})")
    _objective_argument(s)
    s.add_argument("--sigma-from", default="train", metavar="SPLIT|default|paper",
                   help="tune sigma on this split (default train), or use each matcher's 'default' or the 'paper' "
                        "sigma; the tables say which")
    add_bench_config(s)
    add_run_options(s, workers=WORKERS_HELP)
    add_scheduler(s)
    policy_argument(s, "tune sigma for and report under this stop policy")
    s.set_defaults(func=_cmd_bench)


def _add_carry(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("carry", help="how far one sigma carries: chosen on every other frame-set, read on each",
                       description="Leave one frame-set out: sigma chosen (first-match objective) on the train "
                                   "splits of all the others (all frames of a set without one), read on its val "
                                   "split (all frames without one, or PATH:SPLIT); CM and first-match precision "
                                   "with intervals over target instances, beside the set's own best sigma (PIN's "
                                   "rule); SR and CE of the navigation estimate where the set has geometry.")
    s.add_argument("framesets", nargs="+", help="frame-sets, PATH or PATH:SPLIT (at least two)")
    s.add_argument("--matcher", required=True, help="registered matcher (`pin-match list`)")
    add_matcher_config(s)
    s.add_argument("--cache", type=Path, default=outputs.SCORES, help=f"score cache (default {outputs.SCORES})")
    s.add_argument("--bootstrap", type=int, default=1000, help="bootstrap resamples for the 95 %% CIs (default 1000)")
    s.add_argument("--vary", metavar="KEY=V1,V2,...",
                   help="variants of the matcher, one per value of one config key (scored in one pass): each "
                        "variant's rows, then per set the variant chosen on the other sets alone (needs three sets)")
    s.add_argument("--policy", action="append", metavar="POLICY[,POLICY...]",
                   help="read with these stop policies (repeatable; K-of-N or house:topT+MARGIN, e.g. "
                        "--policy 1-of-1,2-of-3 --policy=house:top{1,3}+{0.05,0.1} with shell braces for a grid): "
                        "each policy's rows, then per set the policy (and --vary value) chosen on the other sets "
                        "alone (needs three sets); default 1-of-1, PIN's rule")
    s.add_argument("--json", type=Path, help="write the rows here")
    add_run_options(s, workers=WORKERS_HELP)
    add_scheduler(s)
    s.set_defaults(func=_cmd_carry)


def _add_demo(sub: argparse._SubParsersAction) -> None:
    from pin_match.evaluation.flows.demo import DEMO_OUT, LOOKALIKES, SCANNED

    scanned, real = SCANNED, LOOKALIKES
    s = sub.add_parser("demo", help="the whole job on scanned look-alikes rendered along PIN walks and on real "
                                    "look-alike photos (built if absent)")
    s.add_argument("--matcher", action="append",
                   help=f"matcher for the {scanned.name} set (repeatable; default {', '.join(scanned.matchers)})")
    s.add_argument("--lookalike-matcher", action="append",
                   help=f"matcher for the {real.name} set (repeatable; default {', '.join(real.matchers)})")
    s.add_argument("--no-lookalikes", action="store_true", help=f"the {scanned.name} set only")
    s.add_argument("--out", type=Path, default=DEMO_OUT, help=f"output folder (default {DEMO_OUT})")
    s.add_argument("--seed", type=int, default=0,
                   help="seed of the demo's frame-sets (default 0); a set built with another is built again")
    s.add_argument("--tune", action="store_true",
                   help="score the train splits too and tune sigma there (first-match), instead of the sigmas shipped "
                        "for the seed-0 sets; writes each set's table to ship (demo_sigmas.json in its folder)")
    add_run_options(s, workers=WORKERS_HELP)
    add_scheduler(s)
    s.set_defaults(func=_cmd_demo)
