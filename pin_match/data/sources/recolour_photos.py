"""The recolour set's raw material: scikit-image's bundled photos, where each object lies in them, cut-outs.

The objects are cut out of the photos with GrabCut started from hand-set polygons (OpenCV's
RNG seeded, so the same masks every run); the backgrounds are regions of the same photos that
hold none of the objects, and tinted textures. ``pin_match.data.sources.recolour`` pastes them into frames.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from pin_match.data.compose import cutout, scale_brightness
from pin_match.errors import PinMatchError

GRABCUT_MARGIN = 48  # px of surroundings GrabCut sees around a polygon


class RecolourSetError(PinMatchError, RuntimeError):
    """The real-photo set cannot be built here (scikit-image missing or its photos unreadable)."""


def _skimage_data():
    try:
        import skimage.data
    except ImportError as exc:
        raise RecolourSetError("the real-photo frame-set needs scikit-image (pip install 'pin-match[test]' "
                           "or pip install scikit-image)") from exc
    return skimage.data


@functools.cache
def photo(name: str) -> np.ndarray:
    """A bundled scikit-image photo as RGB uint8 (grey photos are stacked to three channels)."""
    data = _skimage_data()
    try:
        if name in ("motorcycle_left", "motorcycle_right"):
            left, right, _ = data.stereo_motorcycle()
            img = left if name == "motorcycle_left" else right
        else:
            img = getattr(data, name)()
    except Exception as exc:  # a photo that is not bundled is fetched over the network and fails offline
        raise RecolourSetError(f"scikit-image photo {name!r} cannot be loaded offline: {exc}") from exc
    img = np.asarray(img)
    if img.ndim == 2:
        img = np.dstack([img] * 3)
    return np.ascontiguousarray(img[..., :3]).astype(np.uint8)


@dataclass(frozen=True)
class Cutout:
    """Where an object is in a bundled photo: a hand-set polygon (x, y) that GrabCut refines.

    ``background`` is an optional polygon inside ``polygon`` known to be background (a
    same-coloured crate behind the motorcycle that GrabCut would otherwise keep).
    """

    photo: str
    polygon: tuple[tuple[int, int], ...]
    grabcut: bool = True
    background: tuple[tuple[int, int], ...] = ()


def _ellipse(cx: int, cy: int, ax: int, ay: int, n: int = 24) -> tuple[tuple[int, int], ...]:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return tuple((int(round(cx + ax * np.cos(a))), int(round(cy + ay * np.sin(a)))) for a in t)


def _rect(x0: int, y0: int, x1: int, y1: int) -> tuple[tuple[int, int], ...]:
    return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))


CUTOUTS: dict[str, Cutout] = {
    "cup": Cutout("coffee", _rect(75, 15, 485, 390)),
    "motorcycle": Cutout("motorcycle_left", (
        (92, 190), (150, 150), (330, 175), (420, 145), (470, 90), (545, 95), (585, 130), (645, 285), (692, 375),
        (670, 455), (560, 455), (520, 405), (430, 385), (350, 440), (270, 405), (200, 405), (120, 345), (95, 250)),
        background=((572, 150), (620, 150), (620, 255), (583, 255), (565, 205), (568, 190))),
    "motorcycle_right": Cutout("motorcycle_right", (
        (45, 200), (100, 150), (290, 165), (300, 115), (440, 90), (510, 110), (535, 140), (525, 190), (495, 200),
        (500, 265), (590, 285), (630, 360), (625, 440), (560, 455), (490, 420), (420, 380), (300, 440), (250, 400),
        (170, 400), (85, 340), (50, 260))),
    "rocket": Cutout("rocket", ((322, 126), (329, 130), (334, 145), (334, 405), (310, 405), (310, 145), (315, 130)),
                     grabcut=False),
    "shuttle": Cutout("astronaut", ((398, 0), (436, 0), (440, 40), (455, 50), (458, 215), (470, 228), (455, 250),
                                    (440, 272), (395, 272), (360, 228), (352, 215), (380, 200), (380, 60), (395, 40)),
                      grabcut=False),
    "patch": Cutout("astronaut", _ellipse(172, 385, 42, 42)),
    "cat": Cutout("chelsea", _ellipse(225, 150, 215, 160), grabcut=False),
    "helmet": Cutout("astronaut", _ellipse(392, 445, 118, 108)),
}


def _texture(name: str, gains: tuple[float, float, float]) -> Callable[[], np.ndarray]:
    return lambda: scale_brightness(photo(name), gains)


def _region(name: str, x0: int, y0: int, x1: int, y1: int) -> Callable[[], np.ndarray]:
    return lambda: photo(name)[y0:y1, x0:x1]


# Backgrounds: regions of bundled photos that hold none of the objects, and tinted grey textures.
BACKGROUNDS: dict[str, Callable[[], np.ndarray]] = {
    "brick": _texture("brick", (1.15, 0.8, 0.65)),
    "grass": _texture("grass", (0.7, 1.0, 0.6)),
    "gravel": _texture("gravel", (1.0, 0.95, 0.85)),
    "wood": _region("coffee", 480, 0, 600, 400),
    "garage": _region("motorcycle_left", 560, 0, 741, 240),
    "launch_pad": _region("rocket", 0, 0, 280, 427),
    "cameraman": _region("camera", 0, 0, 512, 512),
}


@functools.cache
def cutout_rgba(name: str) -> np.ndarray:
    """The cut-out object as RGBA cropped to its mask (alpha 0 or 255), deterministic (OpenCV's RNG seeded)."""
    cut = CUTOUTS[name]
    img = photo(cut.photo)
    inside = np.zeros(img.shape[:2], np.uint8)
    cv2.fillPoly(inside, [np.array(cut.polygon, np.int32)], 1)
    if cut.background:
        cv2.fillPoly(inside, [np.array(cut.background, np.int32)], 0)
    if cut.grabcut:
        # GrabCut sees the polygon's box plus a margin: its background model comes from the surroundings
        ys, xs = np.nonzero(inside)
        y0, y1 = max(ys.min() - GRABCUT_MARGIN, 0), min(ys.max() + 1 + GRABCUT_MARGIN, img.shape[0])
        x0, x1 = max(xs.min() - GRABCUT_MARGIN, 0), min(xs.max() + 1 + GRABCUT_MARGIN, img.shape[1])
        mask = np.where(inside[y0:y1, x0:x1] > 0, cv2.GC_PR_FGD, cv2.GC_BGD).astype(np.uint8)
        cv2.setRNGSeed(0)
        cv2.grabCut(np.ascontiguousarray(img[y0:y1, x0:x1, ::-1]), mask, None, np.zeros((1, 65)), np.zeros((1, 65)),
                    5, cv2.GC_INIT_WITH_MASK)
        fg = np.zeros_like(inside)
        fg[y0:y1, x0:x1] = np.isin(mask, (cv2.GC_FGD, cv2.GC_PR_FGD))
        # keep the largest connected piece: GrabCut leaves specks of background inside the polygon
        n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
        if n > 1:
            fg = (labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
    else:
        fg = inside
    if not fg.any():
        raise RecolourSetError(f"cutout {name!r} of photo {cut.photo!r} came out empty")
    # the photo stays under alpha 0: warp_rgba interpolates across the outline from real surroundings
    return cutout(img, fg, clear_outside=False)


