"""One matcher's report folder at one sigma: metrics.json, per_category.csv, sizes.csv, views.csv (where the matcher
names the reference view its boxes matched), the paper's tables, plots.

``report`` only assembles: sigma comes from ``pin_match.evaluation.core.sigma``, numbers from
``pin_match.evaluation``, tables from ``pin_match.evaluation.core.tables``, figures from
``pin_match.evaluation.pages.plots``, the page (``report.html``, with galleries) from
``pin_match.evaluation.pages.report_page``.
Every file names the sigma and where it came from (metrics.json: ``sigma``,
``sigma_source``, ``sigma_detail``; the tables: a "sigma from" column and the caption).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.evaluator import EvalContext, evaluate, table_subset
from pin_match.evaluation.core.layout import ReportFiles
from pin_match.evaluation.core.navigation import navigation_sweep, sweep_sigmas
from pin_match.evaluation.core.sigma import SigmaChoice, resolve_sigma
from pin_match.evaluation.core.sizes import best_point_hits, readable, size_table
from pin_match.evaluation.core.stop import FIRST_MATCH, StopPolicy
from pin_match.evaluation.core.sweep import sweep
from pin_match.evaluation.core.tables import latex_table, markdown_table, report_tables
from pin_match.evaluation.core.views import view_table
from pin_match.evaluation.pages.plots import (
    plot_navigation_curves,
    plot_per_category,
    plot_score_distributions,
    plot_sigma_curves,
)
from pin_match.evaluation.pages.report_page import write_report_page
from pin_match.scoring.table import ScoreTable


def report(table: ScoreTable, data: FrameSet | EvalContext, out_dir: str | Path, *,
           sigma: float | SigmaChoice | None = None, thresholds: str | Path | None = None,
           split: str | None = "val", policy: StopPolicy = FIRST_MATCH) -> dict:
    """Evaluate at one sigma and write the report folder; returns metrics.json's content plus ``files``.

    ``data``: the frame-set, or the run's ``EvalContext`` (its labels and bootstrap options).
    ``sigma``: a number (given), a ``SigmaChoice`` (a caller that knows the provenance, e.g. ``bench``),
    or None: then ``thresholds`` (a file, or "paper", tuned for ``policy``), else the matcher's default.
    ``policy``: the stop policy the navigation estimate, its curves and the page's account of each stop read (a
    policy but PIN's rule also writes what it committed to per episode, commits.csv).
    ``files``: each file written, by its name in ``ReportFiles`` (``{"metrics": ".../metrics.json", ...}``; the
    navigation files only where the frame-set has geometry).
    """
    ctx = EvalContext.of(data)
    choice = sigma if isinstance(sigma, SigmaChoice) else \
        resolve_sigma(table.matcher_id, table.meta.get("default_sigma"), sigma, thresholds, policy)
    evaluation = evaluate(table, ctx, choice, split, policy)
    result = evaluation.result
    files = ReportFiles.in_folder(out_dir)
    atomic.write_text(files.per_category, evaluation.per_category.to_csv(index_label="category"))
    overall, per_cat = report_tables(result, evaluation.per_category)
    hits = best_point_hits(table_subset(table, evaluation.frames.frame_id).frames, ctx.fs.visibility,
                           ctx.fs.instance_mask)
    sizes = size_table(evaluation.frames, ctx.fs.visibility, choice.value, hits)
    atomic.write_text(files.sizes, sizes.assign(sigma=choice.value, sigma_source=choice.source).to_csv())
    views = view_table(evaluation.frames, table, choice.value)
    title = f"{table.matcher_id}, split {result['split']}, sigma = {choice.value:g} ({choice.source})"
    atomic.write_text(files.markdown, f"# {title}\n\nsigma: {choice.detail}\n\n{markdown_table(overall)}\n\n"
                                      f"## Per target category\n\n{markdown_table(per_cat)}\n\n"
                                      f"## By the objects' size (pixels)\n\n{markdown_table(readable(sizes))}\n")
    atomic.write_text(files.latex, latex_table(overall, caption=f"{title}.") + "\n"
                      + latex_table(per_cat, caption=f"{title}, per target category.") + "\n")
    plot_sigma_curves(sweep(evaluation.arrays), choice.value, files.sigma_curves, title)
    plot_score_distributions(evaluation.arrays, choice.value, files.score_distributions, title)
    plot_per_category(evaluation.per_category, files.per_category_plot, title)
    for stale in (files.navigation, files.navigation_curves, files.views, files.commits):
        stale.unlink(missing_ok=True)
    if evaluation.commits is not None:
        atomic.write_text(files.commits, evaluation.commits.assign(sigma=choice.value, policy=str(policy)).to_csv(
            index=False))
    if views is not None:
        atomic.write_text(files.views, views.assign(sigma=choice.value, sigma_source=choice.source).to_csv())
    if evaluation.walks is not None:
        atomic.write_text(files.navigation, evaluation.walks.to_csv(index=False))
        curve = navigation_sweep(ctx.placements(table, split), sweep_sigmas(evaluation.arrays.score, policy), policy)
        plot_navigation_curves(curve, choice.value, files.navigation_curves, title)
    write_report_page(files, table, ctx.fs, evaluation)
    # last: a folder without metrics.json is a report that stopped (e.g. on a damaged mask the page reads)
    atomic.write_json(files.metrics, result)
    written = {name: str(path) for name, path in dataclasses.asdict(files).items() if path.exists()}
    return {**result, "files": written}
