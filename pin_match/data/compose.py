"""Frame geometry and compositing, shared by every source that makes frames.

PIN's camera frames are 640x360 portrait; the synthetic renderer, the recolour set and the
look-alike sets all write that size, so a matcher sees the same geometry whichever set it is
scored on. The steps two or more sources need (a seed from names, cutting an object out by
its mask, brightening it, pasting it, fitting a photo into the frame) are written here once.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence

import cv2
import numpy as np

from pin_match.data.agent import FRAME_HEIGHT, FRAME_WIDTH

LETTERBOX_GREY = 114  # the grey of YOLO-style letterboxing: neither black nor white, rare in photos


def stable_seed(*parts: object) -> int:
    """A seed from names and numbers: unlike ``hash``, the same in every process and Python run."""
    return zlib.crc32("/".join(str(p) for p in parts).encode()) & 0x7FFFFFFF


def scale_brightness(image: np.ndarray, gain: float | Sequence[float]) -> np.ndarray:
    """An RGB or RGBA uint8 image with its colour times ``gain`` (one or one per channel), saturating.

    Alpha, when there is one, is kept: brightening an object must not move its outline.
    """
    rgb = np.clip(image[..., :3].astype(np.float32) * np.asarray(gain, np.float32), 0, 255).astype(np.uint8)
    return rgb if image.shape[-1] == 3 else np.dstack([rgb, image[..., 3]])


def rotate_hue(rgb: np.ndarray, hue: int, mask: np.ndarray | None = None) -> np.ndarray:
    """An RGB uint8 image with its hue rotated by ``hue`` (OpenCV units, 0-179); only under ``mask`` when given.

    Pixels outside the mask keep their bytes: an HSV round trip would move them by rounding.
    """
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    hsv[..., 0] = ((hsv[..., 0].astype(np.int32) + hue) % 180).astype(np.uint8)
    rotated = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    if mask is None:
        return rotated
    out = rgb.copy()
    out[mask] = rotated[mask]
    return out


def largest_piece(mask: np.ndarray) -> np.ndarray:
    """The largest 8-connected piece of a 0/1 uint8 mask (all zero when the mask is).

    Automatic masks (GrabCut, a background threshold) leave specks beside the object; one
    source photo shows one object, so the biggest piece is it.
    """
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return np.zeros_like(mask)
    return (labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)


def cutout(rgb: np.ndarray, mask: np.ndarray, *, clear_outside: bool = True) -> np.ndarray:
    """The object under a non-empty ``mask`` as RGBA cropped to the mask's box, alpha 255 on it and 0 elsewhere.

    ``clear_outside`` zeroes the colour under alpha 0, so nothing of the photo's background
    is stored with the object. Without it the photo stays there, and a later warp that
    interpolates across the outline blends the object with its real surroundings, not black.
    """
    ys, xs = np.nonzero(mask)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    on = (mask[y0:y1, x0:x1] > 0).astype(np.uint8)
    rgb = rgb[y0:y1, x0:x1]
    if clear_outside:
        rgb = rgb * on[..., None]
    return np.dstack([rgb, on * 255]).astype(np.uint8)


def paste(image: np.ndarray, mask: np.ndarray, rgba: np.ndarray, x: int, y: int, value: int) -> None:
    """Paste ``rgba`` with its top-left corner at (x, y), in place, clipped to the frame.

    Pixels with at least half alpha replace the image's and take ``value`` in ``mask``: a
    binary rule, so the instance mask is exactly what shows and ground truth stays exact.
    """
    h, w = rgba.shape[:2]
    y0, x0 = max(y, 0), max(x, 0)
    y1, x1 = min(y + h, image.shape[0]), min(x + w, image.shape[1])
    if y1 <= y0 or x1 <= x0:
        return
    sub = rgba[y0 - y:y1 - y, x0 - x:x1 - x]
    on = sub[..., 3] >= 128
    image[y0:y1, x0:x1][on] = sub[..., :3][on]
    mask[y0:y1, x0:x1][on] = value


def room_crop(photo: np.ndarray, rng: np.random.Generator, zoom: float = 1.0) -> np.ndarray:
    """A random crop of ``photo`` at the frame's aspect, resized to the frame, mirrored half the time.

    ``zoom`` is the crop's height as a fraction of the tallest crop that fits: callers that
    want a random zoom draw it from the same generator before calling, so one seed fixes all.
    """
    h, w = photo.shape[:2]
    aspect = FRAME_WIDTH / FRAME_HEIGHT
    ch = int(min(h, w / aspect) * zoom)
    cw = int(round(ch * aspect))
    y = int(rng.integers(0, h - ch + 1))
    x = int(rng.integers(0, w - cw + 1))
    out = cv2.resize(np.ascontiguousarray(photo[y:y + ch, x:x + cw]), (FRAME_WIDTH, FRAME_HEIGHT),
                     interpolation=cv2.INTER_LINEAR if ch < FRAME_HEIGHT else cv2.INTER_AREA)
    return np.ascontiguousarray(out[:, ::-1]) if rng.random() < 0.5 else out


def letterbox(rgb: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Scale a photo to fit the frame and place it at a random height on grey; its mask goes along.

    The photo keeps its aspect (no object is stretched); a landscape photo fills the width.
    """
    h, w = rgb.shape[:2]
    s = min(FRAME_WIDTH / w, FRAME_HEIGHT / h)
    nw, nh = max(int(round(w * s)), 1), max(int(round(h * s)), 1)
    img = cv2.resize(rgb, (nw, nh), interpolation=cv2.INTER_CUBIC if s > 1 else cv2.INTER_AREA)
    m = cv2.resize(mask, (nw, nh), interpolation=cv2.INTER_NEAREST)
    frame = np.full((FRAME_HEIGHT, FRAME_WIDTH, 3), LETTERBOX_GREY, np.uint8)
    out_mask = np.zeros((FRAME_HEIGHT, FRAME_WIDTH), np.uint16)
    y = int(rng.integers(0, FRAME_HEIGHT - nh + 1))
    x = (FRAME_WIDTH - nw) // 2
    frame[y:y + nh, x:x + nw] = img
    out_mask[y:y + nh, x:x + nw] = m
    return frame, out_mask
