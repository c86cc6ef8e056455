"""The pictures every page shows, drawn one way: a frame with its ground truth and points, a target's references.

The report, inspect, compare and index pages all call these, so a frame looks the same on
each (mask outlines in the role colours, the matcher's stored points at its sigma as
crosses) and is written once per page through the page's ``html.Assets``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from markupsafe import Markup

from pin_match.contract.cohort import TargetCohort
from pin_match.contract.matcher import Target
from pin_match.data.frameset import FrameSet
from pin_match.data.images import read_image
from pin_match.evaluation.pages import html
from pin_match.evaluation.pages.gallery import (
    OUTLINE_RGB,
    POINT_RGB,
    REFERENCE_SIZE,
    THUMB_SIZE,
    draw_frame,
    frame_points,
    on_checkerboard,
    thumbnail,
)
from pin_match.scoring.table import ScoreTable


def frame_image(assets: html.Assets, fs: FrameSet, frame_id: str, points: np.ndarray | None = None, *,
                box: int = THUMB_SIZE) -> Markup:
    """The frame with every visible object's outline and ``points`` (x, y) marked, shrunk to ``box``."""
    marks = np.zeros((0, 2), np.float32) if points is None else np.asarray(points, np.float32)
    src = assets.add(("frame", frame_id, box, marks.tobytes()),
                     lambda: thumbnail(draw_frame(fs, frame_id, marks), box))
    return html.image(src, f"frame {frame_id} with mask outlines and {len(marks)} points")


def scored_frame_image(assets: html.Assets, fs: FrameSet, table: ScoreTable, frame_id: str, sigma: float, *,
                       box: int = THUMB_SIZE) -> Markup:
    """``frame_image`` with the points ``table`` stored for the frame at ``sigma`` (none below it)."""
    return frame_image(assets, fs, frame_id, frame_points(table, frame_id, sigma), box=box)


def reference_images(assets: html.Assets, target: Target) -> list[Markup]:
    """An object's reference views on a checkerboard (a failed cut-out shows as a square of background)."""
    return [html.image(assets.add(("ref", target.object_id, k), lambda v=view: on_checkerboard(v), ".png"),
                       f"reference view {k} of {target.object_id}") for k, view in enumerate(target.views)]


def references(assets: html.Assets, target: Target) -> Markup:
    """The reference views as one block, to sit beside a frame."""
    return Markup('<div class="refs">{}</div>').format(html.join(reference_images(assets, target)))


def cohort_members(assets: html.Assets, cohort: TargetCohort, n: int = 3) -> Markup:
    """The ``n`` cohort members closest to the target (its scale's impostors), each titled with its raw score.

    The images are read from the cohort's folder as it was scored; a member whose image is not
    there on this machine is named in its place, with the path looked at.
    """
    shown = []
    for name, score in cohort.closest[:n]:
        path = Path(cohort.folder) / name
        if path.is_file():
            src = assets.add(("cohort", str(path)), lambda p=path: thumbnail(read_image(p), REFERENCE_SIZE))
            shown.append(html.image(src, f"cohort member {name}, raw score {score:.3f}"))
        else:
            shown.append(Markup('<span class="note">{}</span>').format(
                f"cohort member {name}, raw score {score:.3f}: no image at {path} on this machine"))
    return Markup('<div class="refs">{}</div>').format(html.join(shown))


def legend(points: bool = True) -> Markup:
    """What the colours of a drawn frame mean."""
    keys = [html.swatch(OUTLINE_RGB["target"], "target"),
            html.swatch(OUTLINE_RGB["same_category"], "same-category look-alike"),
            html.swatch(OUTLINE_RGB["other"], "other object")]
    if points:
        keys.append(html.swatch(POINT_RGB, "crosses: the matcher's points at sigma (stored, not re-computed)"))
    return Markup('<p class="note">Mask outlines: {}.</p>').format(Markup(", ").join(keys))
