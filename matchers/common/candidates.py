"""Where an instance verifier looks, and the colour it compares: candidate boxes from a patch map, masked histograms.

A prototype patch map says *where* something of the target's kind is, at a stride of tens
of pixels; it cannot say *which* instance. These functions turn the map into a few boxes
worth a closer look (``verify`` then re-embeds each box at the backbone's own scale), and
compare the colours of a box with the reference's. They are pure functions of arrays, so a
hand-made map or image checks them exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pin_match.contract import Crop


@dataclass(frozen=True)
class Candidate:
    """One region of a frame: its box (x0, y0, x1, y1 in frame pixels), its peak cell's score, its points (the
    region's cells, best first) and, once zoomed, the reference view it resembles most."""

    box: tuple[int, int, int, int]
    peak: float
    points: np.ndarray  # (K, 2) frame pixels: the region's cell centres by score, best first
    view: int | None = None


def region_cells(scores: np.ndarray, row: int, col: int, drop: float) -> np.ndarray:
    """Boolean grid: the cells connected (4-neighbours) to (row, col) that score at least its score - ``drop``."""
    keep = (scores >= scores[row, col] - drop).astype(np.uint8)
    _, labels = cv2.connectedComponents(keep, connectivity=4)
    return labels == labels[row, col]


def shaped_box(box: tuple[float, float, float, float], aspect: float, pad: float, min_side: float,
               frame_size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The box ``(x0, y0, x1, y1)`` grown (never shrunk) to width / height = ``aspect``, padded by ``pad`` of its
    size per side, at least ``min_side`` a side, shifted to fit the frame ``(width, height)`` and clipped to it."""
    x0, y0, x1, y1 = box
    width, height = frame_size
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    w, h = max(x1 - x0, min_side), max(y1 - y0, min_side)
    if w / h < aspect:
        w = h * aspect
    else:
        h = w / aspect
    w, h = min(w * (1 + 2 * pad), width), min(h * (1 + 2 * pad), height)
    left = min(max(cx - w / 2, 0.0), width - w)
    top = min(max(cy - h / 2, 0.0), height - h)
    return int(round(left)), int(round(top)), int(round(left + w)), int(round(top + h))


def locate(maps: np.ndarray, crops: list[Crop], frame_shape: tuple[int, int], *, count: int, drop: float,
           aspect: float, pad: float) -> list[Candidate]:
    """Up to ``count`` candidates from per-crop patch maps ``maps`` (n_crops, g, g), best peak first.

    Cells are visited from the best down; a cell whose centre lies in an earlier candidate's
    box is part of that candidate (the crops overlap). A new peak's region is the cells around
    it within ``drop`` of its score; its box is the region's extent shaped to the reference's
    aspect ratio and padded. A candidate is at least two cells a side, so a one-cell peak
    still shows the object's surroundings when zoomed. Its points are the region's cells by
    score, the peak first (whoever reads one point per candidate reads the peak).
    """
    height, width = frame_shape
    grid = maps.shape[-1]
    order = np.argsort(-maps.reshape(-1), kind="stable")
    found: list[Candidate] = []
    for flat in order:
        c, row, col = np.unravel_index(flat, maps.shape)
        crop = crops[c]
        cell_w, cell_h = crop.width / grid, crop.height / grid
        cx, cy = crop.x0 + (col + 0.5) * cell_w, crop.y0 + (row + 0.5) * cell_h
        if any(b.box[0] <= cx < b.box[2] and b.box[1] <= cy < b.box[3] for b in found):
            continue
        region = region_cells(maps[c], row, col, drop)
        rows, cols = np.nonzero(region)
        best_first = np.argsort(-maps[c][rows, cols], kind="stable")
        rows, cols = rows[best_first], cols[best_first]
        extent = (crop.x0 + cols.min() * cell_w, crop.y0 + rows.min() * cell_h,
                  crop.x0 + (cols.max() + 1) * cell_w, crop.y0 + (rows.max() + 1) * cell_h)
        box = shaped_box(extent, aspect, pad, 2 * max(cell_w, cell_h), (width, height))
        points = np.stack([crop.x0 + (cols + 0.5) * cell_w, crop.y0 + (rows + 0.5) * cell_h], 1)
        points = np.minimum(np.rint(points), [width - 1, height - 1]).astype(np.float32)
        found.append(Candidate(box, float(maps[c, row, col]), points))
        if len(found) == count:
            break
    return found


def cell_centre(box: tuple[int, int, int, int], grid: int, cell: int) -> tuple[float, float]:
    """Frame pixels (x, y) of the centre of cell ``cell`` (row-major) of a ``grid`` x ``grid`` map squashed over
    ``box``."""
    row, col = divmod(cell, grid)
    x0, y0, x1, y1 = box
    return x0 + (col + 0.5) * (x1 - x0) / grid, y0 + (row + 0.5) * (y1 - y0) / grid


def square_around(point: tuple[float, float], side: float, frame_size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The square of ``side`` pixels centred on ``point`` (x, y), shifted to fit the frame ``(width, height)`` and
    clipped to it."""
    return shaped_box((point[0], point[1], point[0], point[1]), 1.0, 0.0, side, frame_size)


def mask_aspect(alpha: np.ndarray) -> tuple[float, tuple[int, int, int, int]]:
    """Width / height of the mask's bounding box, and the box (x0, y0, x1, y1)."""
    ys, xs = np.nonzero(alpha)
    box = (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)
    return (box[2] - box[0]) / (box[3] - box[1]), box


def color_histogram(rgb: np.ndarray, weights: np.ndarray, bins: tuple[int, int, int]) -> np.ndarray:
    """Weighted HSV histogram, summing to 1: ``weights`` (H, W) >= 0 say how much each pixel is the object.

    Hue is binned finely and value coarsely, so a red and a blue instance differ while a shadow
    moves little; grey pixels (low saturation) still differ by value (white, grey, black).
    """
    index = hsv_bins(rgb, bins)
    hist = np.bincount(index.ravel(), weights=weights.ravel().astype(np.float64), minlength=int(np.prod(bins)))
    total = hist.sum()
    return hist / total if total > 0 else np.full(len(hist), 1.0 / len(hist))


def hsv_bins(rgb: np.ndarray, bins: tuple[int, int, int]) -> np.ndarray:
    """Each pixel's flat HSV bin (``bins`` = hue, saturation, value counts; OpenCV hue runs 0-179)."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV).astype(np.int64)
    nh, ns, nv = bins
    return ((hsv[..., 0] * nh // 180) * ns + hsv[..., 1] * ns // 256) * nv + hsv[..., 2] * nv // 256


def backprojection(frame: np.ndarray, reference: np.ndarray, bins: tuple[int, int, int]) -> np.ndarray:
    """Per pixel of ``frame``, how much its colour is the reference's rather than the frame's: r / (1 + r), r the
    reference histogram ``reference`` over the frame's own at the pixel's bin (``color``'s ratio histogram,
    Swain & Ballard), in [0, 1): colours common on the target and rare in the frame stand out."""
    index = hsv_bins(frame, bins)
    scene = np.bincount(index.ravel(), minlength=len(reference)) / index.size
    ratio = reference / np.maximum(scene, 1e-12)
    return (ratio / (1.0 + ratio)).astype(np.float32)[index]


def bhattacharyya(p: np.ndarray, q: np.ndarray) -> float:
    """Overlap of two histograms summing to 1: 1 for the same colours, 0 for disjoint ones."""
    return float(np.sqrt(p * q).sum())
