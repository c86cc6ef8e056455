"""What a matcher decided, as pictures: which frames to show, and each frame drawn with its ground truth and points.

A picture never re-runs a matcher: the points are the stored row's (``points_at(sigma)``),
the outlines come from the frame-set's instance masks, the roles from ``labels``. The
selection functions return small DataFrames, so the HTML report, the notebooks and the
tests all show the same frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd

from pin_match.contract.results import NO_VIEW, VIEW_NAMES
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.labels import frame_classes
from pin_match.evaluation.core.views import best_views
from pin_match.scoring.table import ScoreTable, points_at

ROLE_NAMES = ("target", "same-category look-alike", "other", "nothing")  # per class code, labels.TM .. OM
# outline colours (RGB) per visibility role of the frame-set; the points are drawn in yellow with a black rim
OUTLINE_RGB = {"target": (0, 220, 0), "same_category": (255, 40, 40), "other": (40, 160, 255)}
POINT_RGB = (255, 230, 0)
THUMB_SIZE = 320
REFERENCE_SIZE = 96
DEFAULT_CAP = 12


@dataclass(frozen=True)
class Section:
    """One gallery: a title, why its frames were chosen, the frames, and how many qualified before the cap."""

    key: str
    title: str
    why: str
    frames: pd.DataFrame  # scored-frame rows (labels + score) plus ``role``
    n_total: int


def frame_roles(scored: pd.DataFrame) -> pd.Series:
    """The role a frame counts as: its class by the metrics' rule (``labels.frame_classes``), named."""
    return pd.Series(np.asarray(ROLE_NAMES)[frame_classes(scored)], index=scored.index, name="role")


def sections(scored: pd.DataFrame, sigma: float, cap: int = DEFAULT_CAP) -> list[Section]:
    """The report's galleries: false alarms, misses, and each episode's first frame above sigma."""
    scored = scored.assign(role=frame_roles(scored))
    negatives = scored[scored.role != "target"].sort_values(["score", "frame_id"], ascending=[False, True])
    targets = scored[scored.role == "target"].sort_values(["score", "frame_id"])
    first = first_matches(scored, sigma)
    return [
        Section("false_alarms", "Highest-scoring frames without the target (false alarms)",
                "frames where the target is not visible, highest score first", negatives.head(cap), len(negatives)),
        Section("misses", "Lowest-scoring target frames (misses)",
                "frames showing the target, lowest score first", targets.head(cap), len(targets)),
        Section("first_match", "Each episode's first frame above sigma",
                "where the agent would stop at today's rule: was it the target?", first.head(cap), len(first)),
    ]


def first_matches(scored: pd.DataFrame, sigma: float) -> pd.DataFrame:
    """Each episode's first frame at or above sigma (where PIN's agent would stop), in episode order."""
    above = scored[scored.score >= sigma].sort_values(["episode_id", "step"])
    return above.drop_duplicates("episode_id")


def outline(image: np.ndarray, region: np.ndarray, rgb: tuple[int, int, int], thickness: int = 2) -> None:
    """Draw the border of a boolean region onto an RGB image in place."""
    contours, _ = cv2.findContours(region.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    cv2.drawContours(image, contours, -1, rgb, thickness)


def draw_frame(fs: FrameSet, frame_id: str, points: np.ndarray | None = None) -> np.ndarray:
    """The frame with every visible object's mask outlined in its role's colour and ``points`` (x, y) marked."""
    image = np.ascontiguousarray(fs.image(frame_id))
    mask = fs.instance_mask(frame_id)
    thickness = max(2, image.shape[1] // 200)
    for _, v in fs.visibility[fs.visibility.frame_id == frame_id].iterrows():
        outline(image, mask == int(v.mask_value), OUTLINE_RGB.get(v.role, (255, 255, 255)), thickness)
    for x, y in (points if points is not None else np.zeros((0, 2))):
        centre = (int(round(float(x))), int(round(float(y))))
        cv2.circle(image, centre, 3 * thickness, (0, 0, 0), -1)
        cv2.drawMarker(image, centre, POINT_RGB, cv2.MARKER_CROSS, 6 * thickness, thickness)
    return image


def frame_points(table: ScoreTable, frame_id: str, sigma: float) -> np.ndarray:
    """The stored points of one frame at sigma (none below sigma: the matcher did not fire there)."""
    rows = table.frames[table.frames.frame_id == frame_id]
    return points_at(rows.iloc[0], sigma) if len(rows) else np.zeros((0, 2), np.float32)


def frame_view(table: ScoreTable, frame_id: str) -> str | None:
    """The name of the reference view the frame's best box matched; None where the matcher named none."""
    view = best_views(table).get(frame_id, NO_VIEW)
    return None if view == NO_VIEW else VIEW_NAMES[view]


def thumbnail(image: np.ndarray, box: int = THUMB_SIZE) -> np.ndarray:
    """Shrink to fit a ``box`` x ``box`` square keeping the aspect (never enlarge): small files, any orientation."""
    h, w = image.shape[:2]
    scale = box / max(h, w)
    if scale >= 1.0:
        return image
    return cv2.resize(image, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)


def on_checkerboard(rgba: np.ndarray, size: int = REFERENCE_SIZE) -> np.ndarray:
    """A reference view composited on a grey checkerboard, so its transparency (the cut-out) is visible."""
    h, w = rgba.shape[:2]
    scale = size / max(h, w)
    small = cv2.resize(rgba, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)
    yy, xx = np.mgrid[:small.shape[0], :small.shape[1]]
    board = np.where(((yy // 8 + xx // 8) % 2 == 0)[..., None], 200, 150).astype(np.float32)
    board = np.repeat(board, 3, axis=2)
    alpha = small[..., 3:4].astype(np.float32) / 255.0
    return (small[..., :3] * alpha + board * (1.0 - alpha)).astype(np.uint8)


def section_figure(fs: FrameSet, table: ScoreTable, section: Section, sigma: float, max_frames: int = 6):
    """A matplotlib figure of one gallery: per row the drawn frame, then the episode target's three references."""
    import matplotlib.pyplot as plt

    frames = section.frames.head(max_frames)
    fig, axes = plt.subplots(max(1, len(frames)), 4, figsize=(12, 3.2 * max(1, len(frames))), squeeze=False,
                             gridspec_kw={"width_ratios": [2, 1, 1, 1]})
    for ax in axes.ravel():
        ax.axis("off")
    for ax_row, (_, frame) in zip(axes, frames.iterrows()):
        ax_row[0].imshow(draw_frame(fs, frame.frame_id, frame_points(table, frame.frame_id, sigma)))
        view = frame_view(table, frame.frame_id)
        ax_row[0].set_title(f"{frame.frame_id} ({frame.episode_id})\n{frame.role}, score {frame.score:.3g}"
                            + (f", view: {view}" if view else ""), fontsize=8)
        target = fs.target(fs.episode(frame.episode_id).target_object_id)
        for ax, view in zip(ax_row[1:], target.views):
            ax.imshow(on_checkerboard(view))
            ax.set_title(f"reference of {target.object_id}", fontsize=7)
    shown = f"{len(frames)} of {section.n_total}"
    fig.suptitle(f"{table.matcher_id}: {section.title} ({shown}; sigma {sigma:g})")
    fig.tight_layout()
    return fig
