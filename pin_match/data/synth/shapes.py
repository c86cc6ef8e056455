"""Triangle meshes with UVs: the form the renderer draws, and the few primitives the rooms are built from.

A scanned object (``scans``) arrives as one ``Mesh`` whose UVs point into its one texture; the
room's walls, furniture and plants are boxes, cylinders and ellipsoids merged into one mesh per
textured piece, since pybullet's TinyRenderer takes one texture per visual shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Mesh:
    """Vertices (N x 3, metres), UVs (N x 2) and triangles (M x 3, counter-clockwise seen from outside)."""

    vertices: np.ndarray
    uvs: np.ndarray
    faces: np.ndarray

    def normals(self) -> np.ndarray:
        """Area-weighted vertex normals, so curved parts shade smoothly and boxes (split vertices) stay flat."""
        v = self.vertices
        tri = v[self.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        acc = np.zeros_like(v)
        for k in range(3):
            np.add.at(acc, self.faces[:, k], n)
        length = np.linalg.norm(acc, axis=1, keepdims=True)
        return acc / np.where(length > 1e-12, length, 1.0)

    def scaled(self, factors) -> Mesh:
        return Mesh(self.vertices * np.asarray(factors, float), self.uvs, self.faces)

    def moved(self, offset=(0.0, 0.0, 0.0)) -> Mesh:
        return Mesh(self.vertices + np.asarray(offset, float), self.uvs, self.faces)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vertices.min(0), self.vertices.max(0)

    def side_area(self) -> float:
        """About the area the object shows seen from the side and a little above (m^2): its box, 60 % filled."""
        lo, hi = self.bounds
        wide, narrow = sorted((hi[0] - lo[0], hi[1] - lo[1]), reverse=True)
        return float(0.6 * wide * (hi[2] - lo[2] + 0.5 * narrow))


def merge(meshes: list[Mesh]) -> Mesh:
    faces, start = [], 0
    for m in meshes:
        faces.append(m.faces + start)
        start += len(m.vertices)
    return Mesh(np.concatenate([m.vertices for m in meshes]), np.concatenate([m.uvs for m in meshes]),
                np.concatenate(faces))


def _grid(points: np.ndarray, uvs: np.ndarray) -> Mesh:
    """Triangulate an (R x C) grid of points whose rows and columns are surface parameters."""
    rows, cols = points.shape[:2]
    i, j = np.mgrid[:rows - 1, :cols - 1]
    a = (i * cols + j).ravel()
    b, c, d = a + 1, a + cols, a + cols + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return Mesh(points.reshape(-1, 3), uvs.reshape(-1, 2), faces)


def box(sx: float, sy: float, sz: float, uv_metres: float | None = None) -> Mesh:
    """An axis-aligned box centred at the origin; each face maps the whole [0, 1] UV square.

    With ``uv_metres`` the UVs run one unit per that many metres instead, so a texture tiles
    (floors, walls) rather than stretching.
    """
    h = np.array([sx, sy, sz]) / 2
    faces_def = [  # (normal axis, sign, u axis, v axis)
        (0, 1, 1, 2), (0, -1, 1, 2), (1, 1, 0, 2), (1, -1, 0, 2), (2, 1, 0, 1), (2, -1, 0, 1),
    ]
    verts, uvs, faces = [], [], []
    for axis, sign, ua, va in faces_def:
        base = len(verts)
        corners = [(0, 0), (1, 0), (1, 1), (0, 1)]
        for cu, cv in corners:
            p = np.zeros(3)
            p[axis] = sign * h[axis]
            p[ua] = (2 * cu - 1) * h[ua]
            p[va] = (2 * cv - 1) * h[va]
            verts.append(p)
            if uv_metres:
                uvs.append([(p[ua] + h[ua]) / uv_metres, (p[va] + h[va]) / uv_metres])
            else:
                uvs.append([cu, 1 - cv])
        normal = np.zeros(3)
        normal[axis] = sign
        tri = [(0, 1, 2), (0, 2, 3)]
        e1, e2 = verts[base + 1] - verts[base], verts[base + 2] - verts[base]
        if np.dot(np.cross(e1, e2), normal) < 0:
            tri = [(0, 2, 1), (0, 3, 2)]
        faces += [[base + t[0], base + t[1], base + t[2]] for t in tri]
    return Mesh(np.array(verts), np.array(uvs, float), np.array(faces))


def lathe(radii, heights, segments: int = 24, caps: bool = True) -> Mesh:
    """A surface of revolution about z from a profile (radius, height) listed bottom to top.

    U runs around the axis (the seam at angle 0 faces +x), V runs along the profile; caps close
    the ends with flat discs.
    """
    r = np.asarray(radii, float)
    z = np.asarray(heights, float)
    theta = np.linspace(0, 2 * np.pi, segments + 1)
    pts = np.stack([r[:, None] * np.cos(theta), r[:, None] * np.sin(theta), np.broadcast_to(z[:, None],
                                                                                            (len(r), len(theta)))], -1)
    uu, vv = np.meshgrid(theta / (2 * np.pi), 1 - np.linspace(0, 1, len(r)))
    side = _grid(pts, np.stack([uu, vv], -1))
    parts = [side]
    if caps:
        for k, up in ((0, False), (len(r) - 1, True)):
            if r[k] < 1e-6:
                continue
            ring = np.stack([r[k] * np.cos(theta[:-1]), r[k] * np.sin(theta[:-1]), np.full(segments, z[k])], 1)
            verts = np.vstack([[0, 0, z[k]], ring])
            uv = np.vstack([[0.5, 0.5], 0.5 + 0.5 * np.stack([np.cos(theta[:-1]), -np.sin(theta[:-1])], 1)])
            idx = np.arange(segments)
            f = np.stack([np.zeros(segments, int), 1 + idx, 1 + (idx + 1) % segments], 1)
            parts.append(Mesh(verts, uv, f if up else f[:, [0, 2, 1]]))
    return merge(parts)


def cylinder(radius: float, height: float, segments: int = 24, top_radius: float | None = None) -> Mesh:
    """A (possibly tapered) cylinder standing on z = 0."""
    return lathe([radius, radius if top_radius is None else top_radius], [0.0, height], segments)


def ellipsoid(rx: float, ry: float, rz: float, segments: int = 20) -> Mesh:
    """An ellipsoid centred at the origin."""
    phi = np.linspace(0, np.pi, segments // 2 + 1)
    return lathe(np.sin(phi), -np.cos(phi), segments, caps=False).scaled((rx, ry, rz))

