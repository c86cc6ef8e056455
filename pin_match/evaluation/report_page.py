"""``report.html``: one matcher's report folder as a page a person reads, with the frames behind the numbers.

The page shows what the other report files hold (header, tables, plots) and the galleries
of ``gallery.sections``; its images go to ``report_files/`` beside it. Nothing here
computes a metric or runs a matcher.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.evaluation import html
from pin_match.evaluation.gallery import (
    DEFAULT_CAP,
    OUTLINE_RGB,
    POINT_RGB,
    Section,
    draw_frame,
    frame_points,
    on_checkerboard,
    sections,
    thumbnail,
)
from pin_match.scoring.table import ScoreTable

PAGE = "report.html"
ASSETS = "report_files"
PLOTS = (("sigma_curves.png", "metrics against sigma"), ("score_distributions.png", "score distributions per role"),
         ("per_category.png", "metrics per target category"))


def legend() -> str:
    keys = [html.swatch(OUTLINE_RGB["target"], "target"),
            html.swatch(OUTLINE_RGB["same_category"], "same-category look-alike"),
            html.swatch(OUTLINE_RGB["other"], "other object"),
            html.swatch(POINT_RGB, "crosses: the matcher's points at sigma (stored, not re-computed)")]
    return '<p class="note">Mask outlines: ' + ", ".join(keys) + ". A green border marks a frame the matcher " \
        "got right at sigma (target above, anything else below), a red one a frame it got wrong.</p>"


def header(table: ScoreTable, fs: FrameSet, result: dict) -> str:
    config = table.meta.get("config", {})
    return html.definitions([
        ("matcher id", table.matcher_id), ("config", json.dumps(config, sort_keys=True)),
        ("weights", config.get("weights") or "none named in the config"),
        ("frame-set", f"{fs.manifest.get('name', '')} at {fs.root}"), ("frame-set fingerprint", fs.fingerprint),
        ("split", result["split"]), ("sigma", f"{result['sigma']:g} ({result['sigma_source']})"),
        ("sigma from", result["sigma_detail"]), ("date", result.get("date", "")),
    ])


def reference_images(fs: FrameSet, object_id: str, assets: html.Assets) -> list[str]:
    """The target's three views on a checkerboard (a failed cut-out shows as a square of background)."""
    target = fs.target(object_id)
    return [html.image(assets.add(("ref", object_id, k), lambda v=view: on_checkerboard(v), ".png"),
                       f"reference view {k} of target {object_id}") for k, view in enumerate(target.views)]


def frame_figure(fs: FrameSet, table: ScoreTable, frame: pd.Series, sigma: float, assets: html.Assets) -> str:
    """A drawn frame beside its episode target's references, captioned with everything needed to find it again."""
    points = frame_points(table, frame.frame_id, sigma)
    src = assets.add(("frame", frame.frame_id), lambda: thumbnail(draw_frame(fs, frame.frame_id, points)))
    target_id = fs.episode(frame.episode_id).target_object_id
    thumb = html.image(src, f"frame {frame.frame_id} ({frame.role}) with ground-truth outlines and "
                            f"{len(points)} points")
    refs = '<div class="refs">' + "".join(reference_images(fs, target_id, assets)) + "</div>"
    matched = frame.score >= sigma
    lines = [f"score {frame.score:.4g} ({'above' if matched else 'below'} sigma), {len(points)} points",
             f"role: {frame.role}", f"episode {frame.episode_id}, step {frame.step}",
             f"frame {frame.frame_id}", f"target {target_id} ({frame.target_category})"]
    good = (frame.role == "target") == matched
    return html.figure([thumb, refs], lines, "hit" if good else "miss")


def section_html(fs: FrameSet, table: ScoreTable, section: Section, sigma: float, cap: int,
                 assets: html.Assets) -> list[str]:
    shown = len(section.frames)
    capped = f"; capped at {cap}" if section.n_total > shown else ""
    parts = [html.heading(section.title, 2, section.key),
             html.paragraph(f"{section.why}: {shown} of {section.n_total} shown{capped}.", "note")]
    if section.key == "first_match":
        hits = int((section.frames.role == "target").sum())
        parts.append(html.paragraph(f"Among the episodes shown, the first frame above sigma shows the target in "
                                    f"{hits} of {shown}."))
    parts.append(html.gallery([frame_figure(fs, table, f, sigma, assets) for _, f in section.frames.iterrows()]))
    return parts


def write_report_page(path: Path, table: ScoreTable, fs: FrameSet, scored: pd.DataFrame, result: dict,
                      overall: pd.DataFrame, per_category: pd.DataFrame, cap: int = DEFAULT_CAP) -> Path:
    """Write ``report.html`` (and ``report_files/``) into a report folder whose plots are already written."""
    sigma = float(result["sigma"])
    assets = html.Assets(path, ASSETS)
    parts = [header(table, fs, result), html.heading("PIN detection metrics"),
             html.table(overall, f"split {result['split']}, sigma {sigma:g} ({result['sigma_source']})"),
             html.heading("Per target category"), html.table(per_category), html.heading("Plots")]
    parts.append(html.gallery([html.image(name, alt, 440) for name, alt in PLOTS if (path.parent / name).exists()]))
    parts.append(legend())
    for section in sections(scored, sigma, cap):
        parts += section_html(fs, table, section, sigma, cap, assets)
    return html.write_page(path, f"{table.matcher_id} on {result['split']} at sigma {sigma:g}", parts)
