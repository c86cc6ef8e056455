"""Triangle meshes with UVs, built from a few primitives so every object and room stays procedural.

All parts of one object are merged into a single mesh whose UVs point into one texture atlas:
pybullet's TinyRenderer takes one texture per visual shape, so an atlas is what lets a mug have
a patterned body and a plain handle in a single draw.
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

    def moved(self, offset=(0.0, 0.0, 0.0), rotation: np.ndarray | None = None) -> Mesh:
        v = self.vertices if rotation is None else self.vertices @ np.asarray(rotation).T
        return Mesh(v + np.asarray(offset, float), self.uvs, self.faces)

    def in_tile(self, tile: int, grid: int) -> Mesh:
        """Squeeze [0, 1] UVs into one cell of a grid x grid atlas (with a small inset against bleeding)."""
        row, col = divmod(tile, grid)
        inset = 0.02
        uv = np.clip(self.uvs, 0.0, 1.0) * (1 - 2 * inset) + inset
        return Mesh(self.vertices, np.stack([(col + uv[:, 0]) / grid, (row + uv[:, 1]) / grid], 1), self.faces)

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


def split_facing(mesh: Mesh, direction, min_cos: float = 0.9) -> tuple[Mesh, Mesh]:
    """Split off the triangles facing ``direction`` (a front face gets the logo, the rest stays plain)."""
    tri = mesh.vertices[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    sel = n @ np.asarray(direction, float) > min_cos
    return Mesh(mesh.vertices, mesh.uvs, mesh.faces[sel]), Mesh(mesh.vertices, mesh.uvs, mesh.faces[~sel])


def rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def rot_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


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

    U runs around the axis (the seam at angle 0 faces +x, so front prints at U=0.75 face -y),
    V runs along the profile; caps close the ends with flat discs.
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


def torus(major: float, minor: float, arc: float = 2 * np.pi, segments: int = 24, sides: int = 10) -> Mesh:
    """A torus (or an arc of one) in the xz plane around the origin: handles, headbands, rims."""
    a = np.linspace(0, arc, segments + 1)
    b = np.linspace(0, 2 * np.pi, sides + 1)
    aa, bb = np.meshgrid(a, b, indexing="ij")
    rr = major + minor * np.cos(bb)
    pts = np.stack([rr * np.cos(aa), minor * np.sin(bb), rr * np.sin(aa)], -1)
    uvs = np.stack([aa / max(arc, 1e-9), bb / (2 * np.pi)], -1)
    return _grid(pts, uvs)
