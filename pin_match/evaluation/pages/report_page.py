"""``report.html``: one matcher's report folder as a page a person reads, with the frames behind the numbers.

The page shows what the other report files hold (header, tables, plots) and the galleries
of ``gallery.sections``; its images go to ``report_files/`` beside it. Nothing here
computes a metric or runs a matcher.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
from markupsafe import Markup

from pin_match.contract.cohort import TargetCohort
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.evaluator import Evaluation
from pin_match.evaluation.core.layout import ReportFiles
from pin_match.evaluation.core.navigation import MAX_STEPS
from pin_match.evaluation.core.tables import report_tables
from pin_match.evaluation.pages import html
from pin_match.evaluation.pages.gallery import DEFAULT_CAP, Section, frame_points, frame_view, sections
from pin_match.evaluation.pages.pictures import cohort_members, frame_image, legend, references
from pin_match.evaluation.pages.scales import LOOKALIKE, scale_table, target_cohorts
from pin_match.evaluation.pages.sizes_page import sizes_section
from pin_match.evaluation.pages.stop_page import stop_html
from pin_match.evaluation.pages.views_page import views_section
from pin_match.scoring.table import ScoreTable

ASSETS = "report_files"


def page_legend() -> Markup:
    return html.join([legend(), html.paragraph("A green border marks a frame the matcher got right at sigma (target "
                                               "above, anything else below), a red one a frame it got wrong.", "note")])


def header(table: ScoreTable, fs: FrameSet, result: dict) -> Markup:
    config = table.meta.get("config", {})
    return html.definitions([
        ("matcher id", table.matcher_id), ("config", json.dumps(config, sort_keys=True)),
        ("score scale", table.meta.get("score_scale", "not recorded in the table")),
        ("weights", config.get("weights") or "none named in the config"),
        ("frame-set", f"{fs.manifest.get('name', '')} at {fs.root}"), ("frame-set fingerprint", fs.fingerprint),
        ("split", result["split"]), ("sigma", f"{result['sigma']:g} ({result['sigma_source']})"),
        ("sigma from", result["sigma_detail"]), ("date", result.get("date", "")),
    ])


def frame_figure(fs: FrameSet, table: ScoreTable, frame: pd.Series, sigma: float, assets: html.Assets,
                 cohorts: dict[str, TargetCohort]) -> Markup:
    """A drawn frame beside its episode target's references, captioned with everything needed to find it again;
    a look-alike's also beside the target's closest cohort members (what its scale was read against)."""
    points = frame_points(table, frame.frame_id, sigma)
    target_id = fs.episode(frame.episode_id).target_object_id
    matched = frame.score >= sigma
    lines = [f"score {frame.score:.4g} ({'above' if matched else 'below'} sigma), {len(points)} points",
             f"role: {frame.role}", f"episode {frame.episode_id}, step {frame.step}",
             f"frame {frame.frame_id}", f"target {target_id} ({frame.target_category})"]
    view = frame_view(table, frame.frame_id)
    if view is not None:
        lines.insert(1, f"view: {view}")
    good = (frame.role == "target") == matched
    images = [frame_image(assets, fs, frame.frame_id, points), references(assets, fs.target(target_id))]
    cohort = cohorts.get(target_id)
    if cohort is not None and frame.role == LOOKALIKE:
        images.append(cohort_members(assets, cohort))
        lines.append("then the target's closest cohort members: " +
                     ", ".join(f"{n} {s:.3f}" for n, s in cohort.closest[:3]) +
                     f" (raw; this frame {float(cohort.impostors.raw(frame.score)):.3f} raw)")
    return html.figure(images, lines, "hit" if good else "miss")


def section_html(fs: FrameSet, table: ScoreTable, section: Section, sigma: float, cap: int,
                 assets: html.Assets, cohorts: dict[str, TargetCohort]) -> list[Markup]:
    shown = len(section.frames)
    capped = f"; capped at {cap}" if section.n_total > shown else ""
    parts = [html.heading(section.title, 2, section.key),
             html.paragraph(f"{section.why}: {shown} of {section.n_total} shown{capped}.", "note")]
    if section.key == "first_match":
        hits = int((section.frames.role == "target").sum())
        parts.append(html.paragraph(f"Among the episodes shown, the first frame above sigma shows the target in "
                                    f"{hits} of {shown}."))
    parts.append(html.gallery([frame_figure(fs, table, f, sigma, assets, cohorts)
                               for _, f in section.frames.iterrows()]))
    return parts


def scale_html(fs: FrameSet, cohorts: dict[str, TargetCohort], evaluation: Evaluation, sigma: float,
               assets: html.Assets) -> list[Markup]:
    """Each target's cohort beside its scores (``scales``), then per target its references and closest members."""
    targets = fs.episodes.set_index("episode_id").target_object_id
    rows = scale_table(cohorts, evaluation.frames, targets, sigma)
    if rows.empty:
        return []
    figures = [html.figure([references(assets, fs.target(t)), cohort_members(assets, cohorts[t])],
                           [f"target {t}, then its closest cohort members", *(f"{n}: raw {s:.3f}"
                                                                              for n, s in cohorts[t].closest[:3])])
               for t in rows.index]
    return [html.heading("Each target's score scale", 2, "scales"),
            html.paragraph("The score is read against the matcher's scores of a cohort of other objects: 0.5 is the "
                           "raw score of the target's closest cohort members. It carries from house to house as far as "
                           "a house's look-alikes score like those members; a look-alike far above them was not "
                           "foreseen by the cohort. Scores in brackets are raw; a spread at the matcher's min_std "
                           "(default 0.25) is its floor: the closest members agreed more closely than that.", "note"),
            html.table(rows), html.gallery(figures)]


def navigation_html(fs: FrameSet, table: ScoreTable, evaluation: Evaluation, sigma: float,
                    assets: html.Assets) -> list[Markup]:
    """What the agent would do at this sigma: the estimate's numbers, then each episode's stop drawn (the frame the
    goal was placed from, its points) with what it landed on and how far from the target; or why it is absent."""
    parts = [html.heading("What the agent would do (navigation estimate)", 2, "navigation")]
    walks, nav = evaluation.walks, evaluation.result["navigation"]
    if walks is None:
        return [*parts, html.paragraph(f"Not estimated: {nav['missing']}.", "note")]
    m, ci = evaluation.result["metrics"], evaluation.result["ci95"]
    lines = [f"{name} {_value(m.get(key))}{_interval(ci.get(key))}" for key, name in NAVIGATION_NAMES if key in m]
    parts += [html.paragraph("The recorded walk is followed until the policy (" + nav["policy"] + ") commits to a "
                             "frame whose matched points have depth in PIN's 0.5-5 m; their median is the goal. The "
                             "agent then walks from where it committed toward the goal and stands on the floor nearest "
                             "it: the floor map's standable cell nearest the goal or, without a map, the floor below "
                             "the goal, short of it by the agent's radius and a margin. Success: standing within 1 m "
                             "of the target. Exploration after a missed target is not simulated (docs/metrics.md, "
                             "'Navigation').", "note"),
              html.paragraph("; ".join(lines) + f" over {nav['n_episodes']} episodes: " +
                             ", ".join(f"{n} {o}" for o, n in nav["outcomes"].items()) + ".")]
    figures = []
    for _, w in walks.iterrows():
        caption = [f"episode {w.episode_id}: {w.outcome}", f"target {w.target_object_id}"]
        if isinstance(w.rejections, str):  # an approach-verify policy walked up to these and rejected them
            caption.append(f"walked up to and rejected (step:point on:close score): {w.rejections}")
        if w.outcome == "not found":
            never = "never stopped" if pd.isna(w.fired_step) else \
                f"PIN's {MAX_STEPS:,} steps ran out before it stopped" if w.steps >= MAX_STEPS else \
                "rejected every candidate it walked up to" if w.rejected == w.candidates else \
                f"still looking: the window opened at step {w.fired_step:.0f} ran past the walk's end"
            figures.append(html.figure([], [*caption, f"{never}; walk's end {w.d2g:.2f} m from the target",
                                            f"{w.unplaced_candidates} candidates without depth in range"], "miss"))
            continue
        image = frame_image(assets, fs, w.point_frame_id, frame_points(table, w.point_frame_id, sigma))
        looked = "" if w.fired_step == w.stop_step or isinstance(w.rejections, str) else \
            f"fired at step {w.fired_step}, looked on to step {w.stop_step} ({w.candidates} candidates), "
        caption += [f"{looked}stop at step {w.stop_step}, goal from frame {w.point_frame_id}",
                    f"point on: {w.landed_on}, {w.d2g:.2f} m from the target", f"{w.steps} steps, SPL {w.spl:.2f}"]
        figures.append(html.figure([image], caption, "hit" if w.outcome == "success" else "miss"))
    return [*parts, html.gallery(figures)]


NAVIGATION_NAMES = (("sr", "SR %"), ("spl", "SPL %"), ("ce", "CE %"), ("d2g", "D2G m"), ("steps", "Steps"),
                    ("not_found_pct", "not found %"), ("unplaced_pct", "a candidate without depth %"),
                    ("rejections", "rejected per episode"), ("rejected_target_pct", "of them the target %"),
                    ("rejected_lookalike_pct", "of them a look-alike %"), ("rejected_other_pct", "another object %"),
                    ("rejected_nothing_pct", "nothing annotated %"))


def _value(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.2f}"


def _interval(ci: list[float] | None) -> str:
    return f" (95 % CI {ci[0]:.2f}-{ci[1]:.2f})" if ci else ""


def write_report_page(files: ReportFiles, table: ScoreTable, fs: FrameSet, evaluation: Evaluation,
                      cap: int = DEFAULT_CAP) -> Path:
    """Write ``files.page`` (and ``report_files/`` beside it) into a report folder whose plots are already written."""
    result = evaluation.result
    sigma = float(result["sigma"])
    overall, per_category = report_tables(result, evaluation.per_category)
    assets = html.Assets(files.page, ASSETS)
    plots = ((files.sigma_curves, "metrics against sigma"), (files.score_distributions, "score distributions per role"),
             (files.per_category_plot, "metrics per target category"),
             (files.navigation_curves, "navigation estimate against sigma"))
    parts = [header(table, fs, result), html.heading("PIN detection metrics"),
             html.table(overall, f"split {result['split']}, sigma {sigma:g} ({result['sigma_source']})"),
             html.heading("Per target category"), html.table(per_category), html.heading("Plots"),
             html.gallery([html.image(plot.name, alt, 440) for plot, alt in plots if plot.exists()]), page_legend()]
    parts += sizes_section(files.sizes)
    parts += views_section(files.views)
    parts += navigation_html(fs, table, evaluation, sigma, assets)
    parts += stop_html(evaluation.arrays, sigma, evaluation.policy, evaluation.decisions)
    cohorts = target_cohorts(table)
    parts += scale_html(fs, cohorts, evaluation, sigma, assets)
    for section in sections(evaluation.frames, sigma, cap):
        parts += section_html(fs, table, section, sigma, cap, assets, cohorts)
    return html.write_page(files.page, f"{table.matcher_id} on {result['split']} at sigma {sigma:g}", parts)
