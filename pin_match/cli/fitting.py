"""The fitting half of the CLI: ``fit fusion``, ``fit verifier`` and ``fit verifier-report``.

Every carried fitted file (a fusion's weights, the verifier's) comes from one of these
commands; docs/instance-matchers.md gives the command beside each file.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from pin_match.cli.args import add_matcher_config, add_run_options, add_scheduler, engine_run, matcher_overrides
from pin_match.contract.matcher import ConfigError
from pin_match.contract.registry import parse_overrides

TRANSFORM_KEY = "transform"  # of a --component's pairs: the transform of its score, not a config key


def components(specs: list[list[str]]) -> list[tuple[str, dict[str, str], str]]:
    """``--component NAME [KEY=VALUE ...] [transform=T]`` as (name, config overrides, transform)."""
    out = []
    for name, *pairs in specs:
        if "=" in name:
            raise ConfigError(f"--component {' '.join([name, *pairs])!r}: the matcher's name comes first")
        overrides = parse_overrides(pairs)
        out.append((name, overrides, overrides.pop(TRANSFORM_KEY, "identity")))
    return out


def _cmd_fusion(a: argparse.Namespace) -> None:
    from pin_match.fitting.fusion import fit_fusion

    with engine_run(a) as run:
        spec = fit_fusion(a.frameset, components(a.component), a.out, split=a.split, out=a.cache, l2=a.l2, run=run)
    terms = " ".join(f"{c['coef']:+.3g} {c['matcher']}" for c in spec["components"])
    print(f"fusion logit {spec['intercept']:.3g} {terms} on {spec['fitted_on']['frames']} frames "
          f"{spec['fitted_on']['classes']} -> {a.out}\n"
          f"score with: pin-match score FRAMESET --matcher fusion --weights {a.out}")


def _cmd_verifier(a: argparse.Namespace) -> None:
    from pin_match.fitting.verifier import fit_verifier

    with engine_run(a) as run:
        spec = fit_verifier(a.framesets, a.out, split=a.split, overrides=matcher_overrides(a), out=a.features,
                            l2=a.l2, run=run)
    terms = " ".join(f"{c:+.3g} {s}" for s, c in spec["coefs"].items())
    print(f"verifier logit {spec['intercept']:.3g} {terms} on {spec['fitted_on']['candidates']} candidates "
          f"{spec['fitted_on']['classes']} -> {a.out}\n"
          f"score with: pin-match score FRAMESET --matcher verify --weights {a.out}"
          + "".join(f" --cfg {pair}" for pair in a.cfg or []))


def _cmd_verifier_report(a: argparse.Namespace) -> None:
    import pandas as pd

    from pin_match import atomic
    from pin_match.fitting.verifier_report import candidates_figure, report

    signals = dict(signals=tuple(a.signals)) if a.signals else {}
    with engine_run(a) as run:
        result = report(a.train, a.eval, a.features, run=run, **signals)
    with pd.option_context("display.width", 200, "display.max_rows", 500):
        print(pd.DataFrame(result["rows"]).round(3).to_string(index=False))
    print(json.dumps(dict(sigmas=result["sigmas"], paired=result["paired"],
                          candidate_recall=result["candidate_recall"]), indent=1))
    if a.json:
        atomic.write_json(a.json, {k: v for k, v in result.items() if k != "sets"})
    if a.figure:
        fs, labels, table = next(iter(result["sets"].evals.values()))
        spec = result["specs"].get("default") or result["specs"]["all"]
        print(f"wrote {candidates_figure(fs, labels, table, spec, a.figure)}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    from pin_match.outputs import FEATURES, SCORES

    group = sub.add_parser("fit", help="fit the weights of a fitted matcher's file (fusion, verify) on train splits")
    fits = group.add_subparsers(dest="fit", required=True, metavar="{fusion,verifier,verifier-report}",
                                help="what to fit")

    s = fits.add_parser("fusion", help="logistic fusion of component matchers' cached scores (the fusion matcher)")
    s.add_argument("frameset", type=Path, help="frame-set folder, fitted on its --split")
    s.add_argument("--component", nargs="+", action="append", required=True, metavar="NAME [KEY=VALUE ...]",
                   help="a component matcher and its config overrides, transform=identity|log1p for its score "
                        "(default identity); repeat per component, the first giving the fusion's points, e.g. "
                        "--component effnet "
                        "--component effnet layer=blocks.3 img_size=224 --component xfeat transform=log1p")
    s.add_argument("--cache", type=Path, default=SCORES, help=f"score cache of the components (default {SCORES})")

    v = fits.add_parser("verifier", help="logistic verifier of candidate regions' signals (the verify matcher)")
    v.add_argument("framesets", type=Path, nargs="+", help="frame-set folders, fitted together on their --split")
    add_matcher_config(v, "the verify matcher's (signals=... for an ablation)")
    v.add_argument("--features", type=Path, default=FEATURES,
                   help=f"cache of candidate signals (default {FEATURES})")
    for p in (s, v):
        p.add_argument("--out", type=Path, required=True, help="the fitted JSON file to write")
        p.add_argument("--split", default="train", help="the split fitted on (default train)")
        p.add_argument("--l2", type=float, default=1.0, help="L2 penalty on the standardised features (default 1)")
        add_run_options(p, workers="threads decoding frames (default up to 2); with --scheduler local, worker "
                                   "processes", batch_size=True)
        add_scheduler(p)
    s.set_defaults(func=_cmd_fusion)
    v.set_defaults(func=_cmd_verifier)

    r = fits.add_parser("verifier-report", help="the verifier's ablation and how far one sigma carries "
                                                "(docs/instance-matchers.md)")
    r.add_argument("--train", nargs="+", required=True, help="development frame-sets: fitted and tuned on train")
    r.add_argument("--eval", nargs="+", required=True,
                   help="frame-sets read, PATH or PATH:SPLIT (a development set: its val split)")
    r.add_argument("--features", default=str(FEATURES), help="cache of candidate signals")
    r.add_argument("--signals", nargs="+", metavar="SIGNAL",
                   help="the signals computed, the ablation's rows being their subsets (default: verify's default "
                        "signals; add keypoints for its rows, at 0.4x effnet's cost a frame)")
    add_run_options(r, workers="threads decoding frames (default up to 2); with --scheduler local, worker processes",
                    batch_size=True)
    add_scheduler(r)
    r.add_argument("--json", help="write the whole report here")
    r.add_argument("--figure", help="draw the first --eval set's decisions of the default verifier into this PNG")
    r.set_defaults(func=_cmd_verifier_report)
