"""Two matchers on the same frames and split: the paired table, McNemar's test, and the page of their disagreements.

Writes a ``layout.CompareFolder``: ``compare.csv``, ``compare.md`` and ``compare.html`` (images
in ``compare_files/``); the numbers come from ``paired`` and, for AUROC-same per band of the
objects' pixel area (rows ``AUROC-same <band> px``, same resamples), from ``sizes``; the pictures
from ``pictures``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.layout import CompareFolder
from pin_match.evaluation.core.paired import disagreements, first_match_outcomes, mcnemar, paired_comparison
from pin_match.evaluation.core.sigma import SigmaChoice
from pin_match.evaluation.core.sizes import paired_size_rows
from pin_match.evaluation.core.tables import markdown_table
from pin_match.evaluation.pages import html
from pin_match.evaluation.pages.gallery import frame_roles
from pin_match.evaluation.pages.pictures import legend, scored_frame_image
from pin_match.scoring.table import ScoreTable

if TYPE_CHECKING:
    from pin_match.evaluation.core.analysis import BenchRun

COMPARE_THUMB = 240
ASSETS = "compare_files"


@dataclass(frozen=True)
class AtSigma:
    """One side of a comparison: a matcher's score table and the sigma (with its provenance) it is judged at."""

    table: ScoreTable
    sigma: SigmaChoice


@dataclass(frozen=True)
class Comparison:
    """What ``compare`` wrote: B against A on one split."""

    names: tuple[str, str]   # matcher ids of A and B
    paired: pd.DataFrame     # rows = metrics (then AUROC-same per size band, ``sizes``): A, B, B - A and its interval
    test: dict               # McNemar on "the first match is the target"
    summary: list[str]       # the sentences above the table, as on the page
    folder: CompareFolder


def compare(a: AtSigma, b: AtSigma, data: FrameSet | EvalContext, out: str | Path | CompareFolder, *,
            split: str | None = "val", cap: int = 12) -> Comparison:
    """Write the comparison folder (differences are B minus A); ``data``: the frame-set or the run's context."""
    ctx = EvalContext.of(data)
    folder = out if isinstance(out, CompareFolder) else CompareFolder(Path(out))
    names = (a.table.matcher_id, b.table.matcher_id)
    scored_a, scored_b = (ctx.scored(side.table, split) for side in (a, b))
    paired = paired_comparison(scored_a, scored_b, a.sigma.value, b.sigma.value, clusters=ctx.clusters, names=names,
                               boot=ctx.boot)
    bands = paired_size_rows(scored_a, scored_b, ctx.fs.visibility, clusters=ctx.clusters, names=names, boot=ctx.boot)
    attrs, paired = paired.attrs, pd.concat([paired, bands]).rename_axis("Metric")
    paired.attrs.update(attrs)
    test = mcnemar(*first_match_outcomes(scored_a, scored_b, a.sigma.value, b.sigma.value))
    atomic.write_text(folder.csv, paired.to_csv())
    summary = summary_lines(paired, test, names, (a.sigma, b.sigma), split)
    atomic.write_text(folder.markdown, "\n\n".join([f"# {names[1]} vs {names[0]}", *summary,
                                                   markdown_table(paired.round(3))]) + "\n")
    gaps = disagreements(scored_a, scored_b, a.sigma.value, b.sigma.value, cap)
    comparison = Comparison(names, paired, test, summary, folder)
    write_compare_page(comparison, ctx.fs, (a, b), gaps)
    return comparison


def compare_bench(run: BenchRun, split: str = "val") -> list[Comparison]:
    """Every matcher of a loaded bench folder against the first, into its layout's compare folders."""
    first, *others = run.matchers
    side = {m: AtSigma(run.tables[m], SigmaChoice(run.sigmas[m], run.reports[m]["sigma_source"],
                                                  run.reports[m]["sigma_detail"])) for m in run.matchers}
    return [compare(side[first], side[other], run.context, run.layout.compare(first, other), split=split)
            for other in others]


def summary_lines(paired: pd.DataFrame, test: dict, names: tuple[str, str], sigmas: tuple[SigmaChoice, SigmaChoice],
                  split: str | None) -> list[str]:
    a = paired.attrs
    sigma_a, sigma_b = sigmas
    return [f"Split {split or 'all'}; {names[0]} at sigma {sigma_a.value:g} ({sigma_a.source}), {names[1]} at sigma "
            f"{sigma_b.value:g} ({sigma_b.source}).",
            f"Differences are {names[1]} minus {names[0]} on the same {a['n_episodes']} episodes; "
            f"{a['level']:.0%} paired bootstrap intervals, {a['n_boot']} resamples of the {a['n_units']} target "
            "instances (all episodes of a drawn instance together). Gaps under 2 points are noise.",
            f"McNemar (first match is the target, per episode): only {names[0]} right in {test['only_a']}, only "
            f"{names[1]} right in {test['only_b']}, both {test['both']}, neither {test['neither']}; exact two-sided "
            f"p = {test['p_value']:.3g}."]


def write_compare_page(comparison: Comparison, fs: FrameSet, sides: tuple[AtSigma, AtSigma],
                       gaps: pd.DataFrame) -> Path:
    path = comparison.folder.page
    assets = html.Assets(path, ASSETS)
    gaps = gaps.assign(role=frame_roles(gaps))
    names = comparison.names
    figures = []
    for _, f in gaps.iterrows():
        images = [scored_frame_image(assets, fs, s.table, f.frame_id, s.sigma.value, box=COMPARE_THUMB)
                  for s in sides]
        lines = [f"frame {f.frame_id} ({f.role}), episode {f.episode_id}",
                 *(f"{name}: score {score:.4g} ({'above' if score >= s.sigma.value else 'below'} sigma)"
                   for name, s, score in zip(names, sides, (f.score_a, f.score_b)))]
        figures.append(html.figure(images, lines))
    parts = [*(html.paragraph(line) for line in comparison.summary), html.table(comparison.paired.round(3)),
             html.heading("Frames where the two disagree most"),
             html.paragraph(f"One matcher accepts the frame at its sigma and the other rejects it, the largest gap "
                            f"in score percentile first; left {names[0]}, right {names[1]}; "
                            f"{len(gaps)} shown (capped).", "note"), legend(), html.gallery(figures)]
    return html.write_page(path, f"{names[1]} vs {names[0]}", parts)
