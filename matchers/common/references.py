"""PIN's reference preparation for keypoint matchers: six references from the target's three views.

PIN's SuperGlue baseline does not match frames against the raw views: each view's object is
cut out on a white background, in a square padded around its mask, and drawn at two scales
on a 360 x 360 canvas, so near and far objects both find keypoints of their size. Every
keypoint matcher here (SuperGlue, LightGlue, DISK, ALIKED, XFeat) uses the same six references.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

REFERENCE_PAD = 30        # pixels of background kept around the object's mask
REFERENCE_CANVAS = 360    # side of the square canvas every prepared reference is drawn on
REFERENCE_SIDES = (360, 180)  # each view at two scales, so near and far objects both match


def square_box(alpha: np.ndarray, pad: int) -> tuple[int, int, int, int]:
    """The square ``(x0, y0, x1, y1)`` (x1, y1 exclusive) centred on the mask's bounding box.

    Its side is the box's longer side plus ``pad`` on both ends; it may stick out of the image.
    """
    ys, xs = np.nonzero(alpha)
    if not len(xs):
        raise ValueError("square_box: the alpha mask is empty")
    bx0, by0, bx1, by1 = int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1
    side = max(bx1 - bx0, by1 - by0) + 2 * pad
    x0 = bx0 - (side - (bx1 - bx0)) // 2
    y0 = by0 - (side - (by1 - by0)) // 2
    return x0, y0, x0 + side, y0 + side


def take_box(image: np.ndarray, box: tuple[int, int, int, int], fill: Any) -> np.ndarray:
    """The pixels of ``box``; where it leaves the image they are ``fill`` (the background colour)."""
    x0, y0, x1, y1 = box
    out = np.full((y1 - y0, x1 - x0) + image.shape[2:], fill, image.dtype)
    h, w = image.shape[:2]
    sx0, sy0, sx1, sy1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    if sx1 > sx0 and sy1 > sy0:
        out[sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = image[sy0:sy1, sx0:sx1]
    return out


@dataclass(frozen=True)
class ReferenceImage:
    image: np.ndarray  # canvas x canvas uint8 (grayscale, or x 3 RGB when prepared in colour), white background
    mask: np.ndarray   # canvas x canvas bool, the object's pixels


def prepare_references(views: Sequence[np.ndarray], pad: int = REFERENCE_PAD, canvas: int = REFERENCE_CANVAS,
                       sides: Sequence[int] = REFERENCE_SIDES, *, color: bool = False) -> list[ReferenceImage]:
    """PIN's SuperGlue references: white background, square crop around the mask, each view at every side.

    The smaller scales are centred on the canvas. Order: view-major (view 0 at every side, then view 1...).
    Grayscale as SuperPoint reads them; ``color=True`` keeps RGB for detectors trained on colour (DISK, ALIKED).
    """
    out = []
    for view in views:
        alpha = view[..., 3:4].astype(np.float32) / 255.0
        rgb = np.round(view[..., :3] * alpha + 255.0 * (1.0 - alpha)).astype(np.uint8)
        box = square_box(view[..., 3] > 0, pad)
        crop = take_box(rgb, box, 255)
        if not color:
            crop = cv2.cvtColor(crop, cv2.COLOR_RGB2GRAY)
        mask = take_box((view[..., 3] > 0).astype(np.uint8), box, 0)
        for side in sides:
            off = (canvas - side) // 2
            image = np.full((canvas, canvas, *crop.shape[2:]), 255, np.uint8)
            m = np.zeros((canvas, canvas), bool)
            image[off:off + side, off:off + side] = cv2.resize(crop, (side, side), interpolation=cv2.INTER_AREA)
            m[off:off + side, off:off + side] = cv2.resize(mask, (side, side), interpolation=cv2.INTER_NEAREST) > 0
            out.append(ReferenceImage(image=image, mask=m))
    return out
