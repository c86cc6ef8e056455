"""Reading image files: the one place a photo, a reference view or a mask is decoded.

Three readers for three kinds of file, each failing with ``ImageFileError`` and one line naming
the file: ``read_image`` (a photo or frame as RGB, a reference view as RGBA), ``read_label_png``
(a 16-bit single-channel PNG: a frame-set's instance mask or depth in millimetres) and
``read_object_mask`` (an 8-bit cut-out mask of a source photo, 255 = object, as 0/1).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from pin_match.errors import PinMatchError


class ImageFileError(PinMatchError, ValueError):
    """An image or mask file is missing, unreadable, or not what its role needs (size, channels, content)."""


def _decode(path: Path, flag: int, what: str) -> np.ndarray:
    """The decoded file; reading bytes first so a missing file and a corrupt one get different words."""
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        raise ImageFileError(f"cannot read {what} {path}: {exc.strerror or exc}") from exc
    arr = cv2.imdecode(data, flag) if data.size else None
    if arr is None:
        raise ImageFileError(f"corrupt or unreadable {what} {path}")
    return arr


def read_image(path: str | Path, *, rgba: bool = False) -> np.ndarray:
    """Decode an image file to RGB (or, for a reference view, RGBA) uint8."""
    path = Path(path)
    if not rgba:
        return cv2.cvtColor(_decode(path, cv2.IMREAD_COLOR, "image"), cv2.COLOR_BGR2RGB)
    arr = _decode(path, cv2.IMREAD_UNCHANGED, "image")
    if arr.ndim != 3 or arr.shape[2] != 4:
        raise ImageFileError(f"reference image {path} has no alpha channel (RGBA expected)")
    if arr.dtype != np.uint8:
        raise ImageFileError(f"reference image {path} must be 8-bit, got {arr.dtype}")
    return cv2.cvtColor(arr, cv2.COLOR_BGRA2RGBA)


def read_label_png(path: str | Path) -> np.ndarray:
    """Decode a single-channel PNG as stored (a frame's instance mask, or its depth in millimetres)."""
    path = Path(path)
    if not path.is_file() or not path.stat().st_size:
        raise ImageFileError(f"missing or empty file {path}")
    arr = _decode(path, cv2.IMREAD_UNCHANGED, "single-channel image")
    if arr.ndim != 2:
        raise ImageFileError(f"corrupt or unreadable single-channel image {path}")
    return arr


def read_object_mask(path: str | Path, shape: tuple[int, int]) -> np.ndarray:
    """A source photo's cut-out mask (8-bit, above 127 = object) as 0/1 uint8; its photo's ``shape``, not empty."""
    path = Path(path)
    m = _decode(path, cv2.IMREAD_GRAYSCALE, "mask") if path.is_file() else None
    if m is None or m.shape != tuple(shape):
        raise ImageFileError(f"mask {path} is missing, unreadable or not the size of its photo {tuple(shape)}")
    if not (m > 127).any():
        raise ImageFileError(f"mask {path} is empty")
    return (m > 127).astype(np.uint8)
