"""Crop policies: which parts of a frame a matcher looks at, and how points come back.

PIN feeds portrait 640x360 frames to square backbones as two square crops (rows 0-360
and 280-640); a frame is matched when either crop is. ``pin`` generalises this to any
size: square crops of the short side, evenly spaced along the long side, as few as cover
it (two for 640x360). ``whole`` is the full frame (SuperGlue).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pin_match.errors import PinMatchError

POLICIES = ("pin", "whole")


class CropPolicyError(PinMatchError, ValueError):
    """A crop policy that is not one of ``POLICIES``."""


@dataclass(frozen=True)
class Crop:
    x0: int
    y0: int
    width: int
    height: int

    def take(self, image: np.ndarray) -> np.ndarray:
        return image[self.y0:self.y0 + self.height, self.x0:self.x0 + self.width]

    def to_frame(self, points: np.ndarray) -> np.ndarray:
        """Crop pixel coordinates (x, y) -> frame pixel coordinates."""
        return points + np.array([self.x0, self.y0], dtype=points.dtype)


def crop_boxes(height: int, width: int, policy: str = "pin") -> list[Crop]:
    if policy == "whole":
        return [Crop(0, 0, width, height)]
    if policy != "pin":
        raise CropPolicyError(f"unknown crop policy {policy!r}; choose one of {POLICIES}")
    side, long = min(height, width), max(height, width)
    n = 1 if long == side else max(2, math.ceil(long / side))
    offsets = np.round(np.linspace(0, long - side, n)).astype(int).tolist()
    if height >= width:
        return [Crop(0, off, side, side) for off in offsets]
    return [Crop(off, 0, side, side) for off in offsets]
