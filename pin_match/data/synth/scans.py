"""Real scanned objects (Google Scanned Objects) as meshes the renderer draws: read, store compactly, load.

A scan arrives as a Wavefront OBJ (positions in metres, z up, the base near z = 0, UVs into one
texture) and a texture image. ``read_obj`` turns it into the generator's ``Mesh`` (one vertex per
distinct position/UV pair, since the renderer takes one UV per vertex); ``write_scan`` stores it
as a compressed ``.npz`` beside a ``.png`` texture, which is the form a scan folder holds (the one
shipped with pin_match and the ones ``pin-match data prepare gso`` writes), and ``load_scan``
reads that back, checked, with errors that name the file.
"""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pin_match import atomic
from pin_match.data.csv_rows import read_rows
from pin_match.data.images import read_image
from pin_match.data.synth.shapes import Mesh
from pin_match.errors import PinMatchError


class ScanError(PinMatchError, ValueError):
    """A scan file that cannot be read as a textured mesh (names the file)."""


@dataclass(frozen=True)
class Scan:
    """A scanned object: its mesh (metres, z up, base at z = 0, centred on x/y) and its RGB texture."""

    name: str
    mesh: Mesh
    texture: np.ndarray


def read_obj(text: str, where: str = "OBJ") -> Mesh:
    """A triangle mesh from OBJ text (``v``, ``vt`` and ``f`` lines; polygons are fanned into triangles).

    UVs are stored with v measured from the image top, as ``Mesh`` keeps them (OBJ measures from the bottom).
    """
    positions, uvs, corners = [], [], []
    for line in text.splitlines():
        head, *rest = line.split() or [""]
        if head == "v":
            positions.append(rest[:3])
        elif head == "vt":
            uvs.append(rest[:2])
        elif head == "f":
            refs = [c.split("/") for c in rest]
            if len(refs) < 3 or any(len(r) < 2 or not r[1] for r in refs):
                raise ScanError(f"{where}: face without texture coordinates: {line.strip()!r}")
            try:  # OBJ counts from 1; a negative index counts back from the last v or vt read so far
                pairs = [(_index(r[0], len(positions)), _index(r[1], len(uvs))) for r in refs]
            except ValueError:
                raise ScanError(f"{where}: a face index is not a whole number: {line.strip()!r}") from None
            corners += [pair for k in range(1, len(pairs) - 1) for pair in (pairs[0], pairs[k], pairs[k + 1])]
    if not positions or not uvs or not corners:
        raise ScanError(f"{where}: no textured triangles (needs v, vt and f lines)")
    try:
        v = np.asarray(positions, np.float64).reshape(len(positions), 3)
        t = np.asarray(uvs, np.float64).reshape(len(uvs), 2)
    except ValueError:
        raise ScanError(f"{where}: every v line needs 3 numbers and every vt line 2") from None
    idx = np.asarray(corners, np.int64) - 1
    if idx.min() < 0 or idx[:, 0].max() >= len(v) or idx[:, 1].max() >= len(t):
        raise ScanError(f"{where}: a face refers to a vertex or UV that does not exist")
    pairs, inverse = np.unique(idx, axis=0, return_inverse=True)
    uv = t[pairs[:, 1]]
    return Mesh(v[pairs[:, 0]], np.stack([uv[:, 0], 1.0 - uv[:, 1]], 1), inverse.reshape(-1, 3).astype(np.int64))


def _index(ref: str, count: int) -> int:
    """An OBJ index (from 1) as written; a negative one counts back from the ``count`` items read so far."""
    n = int(ref)
    return n + count + 1 if n < 0 else n


def standing(mesh: Mesh) -> Mesh:
    """The mesh moved so its base is at z = 0 and its footprint centred on x = y = 0 (bounds from the vertices)."""
    lo, hi = mesh.bounds
    return mesh.moved((-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]))


def write_scan(path_stem: Path, mesh: Mesh, texture_png: bytes) -> tuple[str, str]:
    """Store a mesh as ``<stem>.npz`` (float32 positions and UVs, int32 triangles) and its texture as ``<stem>.png``.

    Returns the two file names. Written atomically, each; the same mesh gives the same bytes (the
    archive's entries carry a fixed date, where ``np.savez_compressed`` stamps the current time).
    """
    buffer = io.BytesIO()
    arrays = dict(vertices=mesh.vertices.astype(np.float32), uvs=mesh.uvs.astype(np.float32),
                  faces=mesh.faces.astype(np.int32))
    with zipfile.ZipFile(buffer, "w") as archive:
        for key, array in arrays.items():
            entry = io.BytesIO()
            np.lib.format.write_array(entry, array, allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            archive.writestr(info, entry.getvalue(), compress_type=zipfile.ZIP_DEFLATED)
    mesh_file, texture_file = path_stem.with_suffix(".npz"), path_stem.with_suffix(".png")
    atomic.write_bytes(mesh_file, buffer.getvalue())
    atomic.write_bytes(texture_file, texture_png)
    return mesh_file.name, texture_file.name


def load_scan(folder: Path, name: str, mesh_file: str, texture_file: str) -> Scan:
    """The scan ``name`` stored by ``write_scan`` in ``folder``; a missing or damaged file is a ``ScanError``."""
    path = folder / mesh_file
    try:
        with np.load(path) as data:
            vertices, uvs, faces = (np.asarray(data[k]) for k in ("vertices", "uvs", "faces"))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        raise ScanError(f"{path}: not a scan mesh ({type(exc).__name__}: {exc})") from None
    if (vertices.ndim != 2 or vertices.shape[1] != 3 or uvs.shape != (len(vertices), 2) or faces.ndim != 2
            or faces.shape[1] != 3 or len(faces) == 0 or faces.min() < 0 or faces.max() >= len(vertices)):
        raise ScanError(f"{path}: not a scan mesh (vertices {vertices.shape}, uvs {uvs.shape}, faces {faces.shape})")
    texture = read_image(folder / texture_file)
    return Scan(name, Mesh(vertices.astype(np.float64), uvs.astype(np.float64), faces.astype(np.int64)), texture)


# ------------------------------------------------------------------ a scan folder
# the scans the default set uses, as `pin-match data prepare gso` writes a folder (NOTICE.md there names each one)
PACKAGED_SCANS = Path(__file__).resolve().with_name("gso")
SCAN_COLUMNS = ("scan", "mesh", "texture", "source", "licence")
FAMILY_COLUMNS = ("family", "scan", "split", "difference")
DIFFERENCES = ("print", "colour", "shape")  # how an instance differs from its family's other members


@dataclass(frozen=True)
class Member:
    """One instance of a look-alike family: its scan, its split and how it differs from its siblings."""

    family: str
    scan: str
    split: str
    difference: str


@dataclass(frozen=True)
class ScanFolder:
    """A folder of scans (``scans.csv``: file names, source, licence) and the families drawn from them
    (``families.csv``: family, scan, split, difference), checked when opened."""

    root: Path
    scans: dict[str, dict[str, str]]
    members: tuple[Member, ...]

    @classmethod
    def open(cls, root: str | Path = PACKAGED_SCANS) -> ScanFolder:
        root = Path(root)
        scans = {r["scan"]: r for r in read_rows(root / "scans.csv", SCAN_COLUMNS, ScanError)}
        members = tuple(Member(r["family"], r["scan"], r["split"], r["difference"])
                        for r in read_rows(root / "families.csv", FAMILY_COLUMNS, ScanError))
        seen: set[str] = set()
        for m in members:
            where = f"{root / 'families.csv'}: scan {m.scan!r}"
            if m.scan not in scans:
                raise ScanError(f"{where} is not in {root / 'scans.csv'}")
            if m.scan in seen:
                raise ScanError(f"{where} is listed twice (an instance belongs to one family and one split)")
            if m.split not in ("train", "val") or m.difference not in DIFFERENCES:
                raise ScanError(f"{where}: split must be train or val and difference one of {list(DIFFERENCES)}, "
                                f"got {m.split!r} and {m.difference!r}")
            seen.add(m.scan)
        return cls(root, scans, members)

    def load(self, name: str) -> Scan:
        row = self.scans[name]
        return load_scan(self.root, name, row["mesh"], row["texture"])

