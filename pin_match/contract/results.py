"""What a matcher returns for an image (``MatchResult``), the caller's threshold rule, and what makes a result or a
target's notes unusable (one line each: ``Matcher`` checks every result, ``check_matcher`` and the scoring engine a
target's notes; None when nothing is wrong)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

VIEW_NAMES = ("frontal", "back", "top")  # the reference views per target by index (frontal after a 30 deg yaw)
N_VIEWS = len(VIEW_NAMES)  # a box's view indexes them
NO_VIEW = -1  # the view of a result whose boxes name none


def _point_array(a: Any) -> np.ndarray:
    return np.asarray(a, dtype=np.float32).reshape(-1, 2) if a is not None else np.zeros((0, 2), np.float32)


@dataclass
class MatchResult:
    """One image's verdict; ``points_at(sigma)`` recovers the coordinates for any threshold."""

    score: float
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))  # (K, 2) x, y
    point_scores: np.ndarray | None = None   # (K,); None = every point carries the frame score
    crop_scores: np.ndarray | None = None    # one score per crop of the crop policy
    heatmap: np.ndarray | None = None        # low-resolution score map (per crop: n_crops x h x w)
    boxes: np.ndarray | None = None          # (M, 4) x0, y0, x1, y1 in image pixels
    box_scores: np.ndarray | None = None     # (M,)
    box_views: np.ndarray | None = None      # (M,) the reference view (index into Target.views) each box matched best

    def __post_init__(self) -> None:
        self.points = _point_array(self.points)
        if self.point_scores is not None:
            self.point_scores = np.asarray(self.point_scores, dtype=np.float32).reshape(-1)

    def scores_of_points(self) -> np.ndarray:
        if self.point_scores is None:
            return np.full(len(self.points), self.score, np.float32)
        return self.point_scores

    def best_view(self) -> int:
        """The reference view its best box (the highest box score; the first among equals) matched, or ``NO_VIEW``
        when the matcher named no views: what a score table keeps of the boxes, so a report can say which view
        matched."""
        if self.box_views is None or not len(self.box_views):
            return NO_VIEW
        return int(np.asarray(self.box_views)[int(np.argmax(np.asarray(self.box_scores, np.float64)))])

    def points_at(self, sigma: float) -> np.ndarray:
        """The target's coordinates under threshold sigma (empty when the frame is not matched)."""
        return points_above(self.score, self.points, self.scores_of_points(), sigma)


def points_above(score: float, points: np.ndarray, point_scores: np.ndarray, sigma: float) -> np.ndarray:
    """The caller's threshold rule: no points unless the frame is matched, then the points scoring >= sigma."""
    if score < sigma:
        return np.zeros((0, 2), np.float32)
    return points[point_scores >= sigma]


def notes_problem(notes: object) -> str | None:
    """Why a matcher's ``target_notes()`` cannot be stored with a score table (JSON text), or None."""
    if not isinstance(notes, dict):
        return f"target_notes() returned {type(notes).__name__}, expected a dict"
    try:
        json.dumps(notes, allow_nan=False)
    except (TypeError, ValueError) as exc:
        return f"target_notes() must hold JSON values (text, finite numbers, lists, dicts): {exc}"
    return None


def points_problem(r: MatchResult, height: int, width: int) -> str | None:
    if not np.isfinite(r.points).all():
        return "returned non-finite points"
    x, y = r.points[:, 0], r.points[:, 1]
    if len(r.points) and ((x < 0).any() or (y < 0).any() or (x >= width).any() or (y >= height).any()):
        return f"returned points outside the {width}x{height} image"
    if r.point_scores is not None and r.point_scores.shape != (len(r.points),):
        return f"returned {len(r.point_scores)} point scores for {len(r.points)} points"
    if r.point_scores is not None and not np.isfinite(r.point_scores).all():
        return "returned non-finite point scores"
    return None


def extras_problem(r: MatchResult) -> str | None:
    if r.crop_scores is not None and not np.isfinite(r.crop_scores).all():
        return "returned non-finite crop scores"
    if r.boxes is not None and (r.box_scores is None or len(r.box_scores) != len(np.asarray(r.boxes).reshape(-1, 4))):
        return "returned boxes without one box score each"
    if r.box_views is not None:
        views = np.asarray(r.box_views)
        if r.boxes is None or views.shape != (len(np.asarray(r.boxes).reshape(-1, 4)),) \
                or views.dtype.kind not in "iu" or (len(views) and (views.min() < 0 or views.max() >= N_VIEWS)):
            return f"returned box views that are not one view index (0-{N_VIEWS - 1}) per box"
    return None
