"""Side-by-side benchmark: score (cached), choose sigma, report on val, one table for all matchers.

This is the toolkit's main job (``pin-match demo`` runs it on each of its sets: ``demo``).
By default sigma is tuned on the train split and applied to val, never tuned on val;
``SigmaRule.source`` can name another tuning split, "default" (each matcher's default), "paper"
(``paper_thresholds.json``, package data) or a thresholds file (a ``Path``: a table of sigmas by
matcher id, such as the demo's shipped ones). Whatever the choice, every row of every table says it.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from pin_match import atomic
from pin_match.contract.registry import create_matcher, get_matcher_class
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.analysis import BenchRun
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.layout import BenchLayout
from pin_match.evaluation.core.policies import tune_policy
from pin_match.evaluation.core.sigma import SigmaChoice, load_threshold, resolve_sigma, tuned_choice
from pin_match.evaluation.core.stop import FIRST_MATCH, StopPolicy
from pin_match.evaluation.core.tables import latex_table, markdown_table, report_row, side_by_side, sigma_caption
from pin_match.evaluation.core.tuning import DEFAULT_OBJECTIVE, tune, write_thresholds
from pin_match.evaluation.flows.report import report
from pin_match.scoring.api import score_many
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.table import ScoreTable
from pin_match.scoring.walkups import walkup_scorer

REPORT_SPLIT = "val"


class BenchError(PinMatchError, ValueError):
    """A bench cannot choose sigma as asked on this frame-set."""


class Stopwatch:
    """Wall seconds per named step, in the order the steps ran: where a bench or the demo spends its time.

    ``within(scope)`` is the same watch naming its steps ``name (scope)``, for one of several
    benches that share it; a step's ``detail`` (how much work it did) joins the scope in brackets.
    """

    def __init__(self, seconds: dict[str, float] | None = None, scope: str = "") -> None:
        self.seconds: dict[str, float] = {} if seconds is None else seconds
        self.scope = scope

    def within(self, scope: str) -> Stopwatch:
        return Stopwatch(self.seconds, scope)

    @contextmanager
    def step(self, name: str, detail: str = "") -> Iterator[None]:
        said = ", ".join(part for part in (self.scope, detail) if part)
        key = f"{name} ({said})" if said else name
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[key] = self.seconds.get(key, 0.0) + time.perf_counter() - start

    def breakdown(self) -> str:
        """One line per step with its seconds and share of the total, then the total."""
        total = sum(self.seconds.values())
        width = max([len(k) for k in self.seconds] + [5])
        lines = [f"{name:<{width}} {s:7.1f} s {s / total if total else 0.0:6.1%}" for name, s in self.seconds.items()]
        return "\n".join([*lines, f"{'total':<{width}} {total:7.1f} s"])


@dataclass(frozen=True)
class SigmaRule:
    """How a bench sets each matcher's sigma: tuned on the split ``source`` for ``objective`` under ``policy`` (the stop
    policy the reports then read), or ``source`` "default", "paper" or a thresholds file (a ``Path``)."""

    source: str | Path = "train"
    objective: str = DEFAULT_OBJECTIVE
    policy: StopPolicy = FIRST_MATCH


@dataclass(frozen=True)
class Bench:
    """What ``bench`` wrote: the joint table, each matcher's report, and the folder as ``load_bench`` would read it
    (the matchers in the order they were benched, so ``compare_bench`` compares each with the first)."""

    joint: pd.DataFrame
    results: list[dict]
    run: BenchRun

    @property
    def caption(self) -> str:
        return sigma_caption([report_row(r) for r in self.results], REPORT_SPLIT)


def bench(data: FrameSet | str | Path | EvalContext, matchers: Sequence[str] | Mapping[str, dict],
          out: str | Path | BenchLayout, *, sigma: SigmaRule = SigmaRule(), run: RunOptions = DEFAULT_RUN,
          watch: Stopwatch | None = None) -> Bench:
    """Run every matcher through score -> sigma -> report (val); write the joint tables under ``out``.

    ``matchers``: names, or a mapping of name to config overrides. ``data``: the frame-set, or the
    run's ``EvalContext`` (its labels, built once for every matcher, and bootstrap options). All
    matchers are scored first, together in one pass over the frames (one bar: each frame decoded once,
    a part several matchers share run once), then tuned and reported (one bar). ``watch`` collects
    the seconds of each step, with the number of frames scored. ``sigma``: where each sigma comes from, and
    the stop policy it is tuned for and the reports read (PIN's first match by default).
    """
    from tqdm import tqdm

    configs = dict(matchers) if isinstance(matchers, Mapping) else {name: {} for name in matchers}
    for name in configs:  # an unknown name fails before any matcher runs
        get_matcher_class(name)
    ctx = EvalContext.of(data)
    splits = sorted(set(ctx.fs.episodes.split))
    sigma_from = sigma.source
    tuning = not isinstance(sigma_from, Path) and sigma_from not in ("default", "paper")
    if tuning and sigma_from not in splits:
        raise BenchError(f"frame-set {ctx.fs.root} has no {sigma_from!r} split to tune sigma on (it has {splits}): "
                         f"pass --sigma-from with one of {splits} (tuning on the reported split {REPORT_SPLIT!r} is "
                         "optimistic), 'default' for each matcher's default sigma, or 'paper' for the paper's")
    layout = out if isinstance(out, BenchLayout) else BenchLayout(Path(out))
    watch = watch or Stopwatch()
    scored_split = None if tuning else REPORT_SPLIT  # no tuning: val is all it needs
    n_frames = len(ctx.fs.split(scored_split).frames)
    built = {name: create_matcher(name, **(cfg or {})) for name, cfg in configs.items()}
    with watch.step(f"score {' + '.join(configs)}", f"{n_frames} frames, one pass"):
        tables = dict(zip(configs, score_many(ctx.fs, list(built.values()), split=scored_split, out=layout.scores,
                                              run=run)))
    if ctx.walk_ups is None:  # an approach-verify policy walks up to candidates: rendered and scored on demand
        ctx.walk_ups = walkup_scorer(ctx.fs, built.values(), layout.scores, run)
    results, tuned = [], {}
    with watch.step("tune + report"):
        for name in tqdm(configs, desc="tune + report", unit="matcher", disable=not run.progress,
                         dynamic_ncols=True):
            choice, tuned[name] = _choose(tables[name], ctx, sigma, layout.thresholds(name))
            results.append(report(tables[name], ctx, layout.report(name), sigma=choice, split=REPORT_SPLIT,
                                  policy=sigma.policy))
        rows = [report_row(r) for r in results]
        joint = side_by_side(rows)
        caption = sigma_caption(rows, REPORT_SPLIT)
        atomic.write_text(layout.table("md"), f"{caption}\n\n{markdown_table(joint)}\n")
        atomic.write_text(layout.table("tex"), latex_table(joint, caption=caption) + "\n")
        atomic.write_text(layout.table("csv"), joint.to_csv())
    reports = {name: {k: v for k, v in r.items() if k != "files"} for name, r in zip(configs, results)}
    run_loaded = BenchRun(layout, ctx, tables, {name: float(r["sigma"]) for name, r in reports.items()}, reports,
                          {name: result for name, result in tuned.items() if result is not None})
    return Bench(joint, results, run_loaded)


def _choose(table: ScoreTable, ctx: EvalContext, rule: SigmaRule,
            threshold_file: Path) -> tuple[SigmaChoice, dict | None]:
    """The sigma applied, and the tuning result when it was tuned (written to ``threshold_file`` for the record,
    passed on in memory). Without tuning, a thresholds file an earlier run left there is removed: it would be
    read back as this run's."""
    sigma_from, objective, policy = rule.source, rule.objective, rule.policy
    if isinstance(sigma_from, Path) or sigma_from in ("default", "paper"):
        threshold_file.unlink(missing_ok=True)
        if sigma_from == "default":
            return resolve_sigma(table.matcher_id, table.meta.get("default_sigma")), None
        return load_threshold(sigma_from, table.matcher_id, policy), None
    result = tune(table, ctx, objective=objective, split=sigma_from) if policy == FIRST_MATCH else \
        tune_policy(table, ctx, policy, objective=objective, split=sigma_from)
    write_thresholds(result, threshold_file)
    return tuned_choice(result, f"tuned on {ctx.fs.root}, written to {threshold_file}"), result
