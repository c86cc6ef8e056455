"""A room's clutter: the products of a lived-in house that are neither the target nor one of the episode's distractors.

PIN's houses are HM3D scans full of real things, with the episode's objects inserted among them;
only the inserted ones are annotated. Here the clutter is of two kinds, both background (mask
value 0) in the instance mask, as a scan's own things are in PIN's:

- **scanned products** of the split's other families (never of a family the house's annotated
  objects belong to, since each of those may be a target): real products at real size on shelves,
  tables and floors;
- **colour doubles**: for every annotated object of the episode, a box or a can of about its size
  wearing patches of its own texture, cut where its surface is (area-weighted), in a new layout.
  So no annotated object's colours are unique in its room by construction: a matcher that finds
  the target by colour alone meets things of the target's colours that are not the target, as in
  a real house, while the print and the shape still tell them apart.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from pin_match.data.synth.objects import ObjectSpec
from pin_match.data.synth.shapes import Mesh, box, cylinder

SCANNED = (6, 10)  # scanned products of other families per house, drawn uniformly in this range
DOUBLE_SCALE = (0.75, 1.25)  # a colour double's size against its object's, per dimension
DOUBLE_CELLS = (3, 6)  # its texture is a grid of this many patches a side
PATCH = 20  # texture pixels a patch is cut from (of a 256 px atlas)
TILE = 256


def choose_scanned(pool: Sequence[ObjectSpec], house: Sequence[ObjectSpec],
                   rng: np.random.Generator) -> list[ObjectSpec]:
    """Scanned clutter for a house: instances of ``pool`` (the house's split) of families the house's annotated
    objects (``house``) do not belong to, since any of those may be a target, in ``pool`` order."""
    families = {o.category for o in house}
    free = [s for s in pool if s.category not in families]
    count = min(len(free), int(rng.integers(SCANNED[0], SCANNED[1] + 1)))
    return [free[k] for k in sorted(rng.choice(len(free), count, replace=False))]


def surface_uvs(mesh: Mesh, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` points drawn uniformly over the mesh's surface, as texture coordinates (u, v from the top)."""
    tri = mesh.vertices[mesh.faces]
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    faces = rng.choice(len(area), count, p=area / area.sum())
    a, b = rng.random(count), rng.random(count)
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    uv = mesh.uvs[mesh.faces[faces]]
    return uv[:, 0] + a[:, None] * (uv[:, 1] - uv[:, 0]) + b[:, None] * (uv[:, 2] - uv[:, 0])


def used_texels(mesh: Mesh, shape: tuple[int, int]) -> np.ndarray:
    """The texels some triangle of the mesh covers (a scan's atlas leaves the rest black)."""
    height, width = shape
    corners = np.round(mesh.uvs[mesh.faces] * [width, height]).astype(np.int32)
    used = np.zeros((height, width), np.uint8)
    cv2.fillPoly(used, list(corners), 1)
    return used.astype(bool)


def double_texture(mesh: Mesh, texture: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A patchwork of the object's own texture: each cell a patch cut around a point drawn on its surface, texels the
    surface does not use filled with the colour at that point. Same colours in about the same shares, no print."""
    cells = int(rng.integers(DOUBLE_CELLS[0], DOUBLE_CELLS[1] + 1))
    height, width = texture.shape[:2]
    used = used_texels(mesh, (height, width))
    side = TILE // cells
    out = np.empty((cells * side, cells * side, 3), np.uint8)
    for k, (u, v) in enumerate(surface_uvs(mesh, cells * cells, rng)):
        col, row = int(np.clip(u * width, 0, width - 1)), int(np.clip(v * height, 0, height - 1))
        r0, c0 = int(np.clip(row - PATCH // 2, 0, height - PATCH)), int(np.clip(col - PATCH // 2, 0, width - PATCH))
        patch = texture[r0:r0 + PATCH, c0:c0 + PATCH].copy()
        patch[~used[r0:r0 + PATCH, c0:c0 + PATCH]] = texture[row, col]
        i, j = divmod(k, cells)
        out[i * side:(i + 1) * side, j * side:(j + 1) * side] = cv2.resize(patch, (side, side),
                                                                           interpolation=cv2.INTER_LINEAR)
    return out


def colour_double(mesh: Mesh, texture: np.ndarray, rng: np.random.Generator) -> tuple[Mesh, np.ndarray]:
    """A box or a can of about the object's size in its colours (``double_texture``), standing on z = 0, centred."""
    lo, hi = mesh.bounds
    sx, sy, sz = (hi - lo) * rng.uniform(*DOUBLE_SCALE, 3)
    if rng.random() < 0.5:
        shape = box(float(sx), float(sy), float(sz)).moved((0.0, 0.0, float(sz) / 2))
    else:
        shape = cylinder(float(max(sx, sy)) / 2, float(sz))
    return shape, double_texture(mesh, texture, rng)
