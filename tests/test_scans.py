"""Scanned objects: OBJ to mesh, the compact stored form, scan folders and the folder shipped with pin_match."""

from __future__ import annotations

import csv
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from pin_match.data.synth.scans import (
    PACKAGED_SCANS,
    ScanError,
    ScanFolder,
    load_scan,
    read_obj,
    standing,
    write_scan,
)
from pin_match.data.synth.shapes import Mesh

# a unit square as one quad, then a triangle that reuses position 1 with another UV (5) and positions 2, 3
QUAD_OBJ = """# a comment
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.25 0.1
f 1/1 2/2 3/3 4/4
f 1/5/1 3/3/1 2/2/1
"""


def at(path) -> str:
    """A path as a regular expression that matches it literally."""
    return re.escape(str(path))


def corners(mesh: Mesh) -> list[tuple[tuple[float, ...], ...]]:
    """Each triangle as its three corners (x, y, z, u, v), in the triangle's order: independent of vertex order."""
    table = np.hstack([mesh.vertices, mesh.uvs])
    return [tuple(tuple(float(c) for c in table[i]) for i in face) for face in mesh.faces]


def same_triangles(got, expected) -> bool:
    """Equal as sets of triangles, each triangle up to a rotation of its corners (which keeps its winding)."""
    def canon(tri):
        k = tri.index(min(tri))
        return tri[k:] + tri[:k]
    return sorted(map(canon, got)) == sorted(map(canon, expected))


def test_read_obj_fans_polygons_splits_uv_seams_and_flips_v():
    mesh = read_obj(QUAD_OBJ, "quad.obj")
    assert len(mesh.vertices) == 5  # 4 positions, position 1 twice (UVs 1 and 5)
    assert mesh.faces.shape == (3, 3) and mesh.faces.dtype == np.int64
    a, b, c, d = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.0)
    expected = [  # OBJ v measured from the bottom becomes 1 - v, from the top
        ((*a, 0.0, 1.0), (*b, 1.0, 1.0), (*c, 1.0, 0.0)),  # the quad 1 2 3 4 fanned: 1 2 3 ...
        ((*a, 0.0, 1.0), (*c, 1.0, 0.0), (*d, 0.0, 0.0)),  # ... and 1 3 4
        ((*a, 0.25, 0.9), (*c, 1.0, 0.0), (*b, 1.0, 1.0)),  # vt 0.25 0.1 -> uv (0.25, 0.9)
    ]
    assert same_triangles([tuple(tuple(round(x, 9) for x in p) for p in t) for t in corners(mesh)], expected)


def test_read_obj_negative_indices_count_back_from_what_was_read():
    absolute = read_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    relative = read_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf -3/-3 -2/-2 -1/-1\n"
                        "v 5 5 5\nvt 0.5 0.5\n")  # read later: not what -1 meant when the face was read
    assert same_triangles(corners(relative), corners(absolute))
    assert len(relative.vertices) == 3  # the unused position and UV make no vertex


@pytest.mark.parametrize("text, message", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1 2 3\n", "face without texture coordinates: 'f 1 2 3'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1//1 2//1 3//1\n", "face without texture coordinates"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no textured triangles"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 4/1\n", "a face refers to a vertex or UV that does not exist"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 -4/1\n", "a face refers to a vertex or UV that does not exist"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 x/1\n", "a face index is not a whole number"),
    ("v 0 0 0\nv 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\n", "every v line needs 3 numbers"),
])
def test_read_obj_errors_name_where(text, message):
    with pytest.raises(ScanError, match=rf"^google_objects/Mug/model_0\.obj: {message}"):
        read_obj(text, "google_objects/Mug/model_0.obj")


def test_standing_centres_the_footprint_on_the_floor():
    mesh = standing(read_obj("v 1 2 3\nv 3 2 3\nv 1 6 5\nvt 0 0\nf 1/1 2/1 3/1\n"))
    assert mesh.vertices.tolist() == [[-1.0, -2.0, 0.0], [1.0, -2.0, 0.0], [-1.0, 2.0, 2.0]]


def _png(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", rgb[..., ::-1])
    assert ok
    return buf.tobytes()


def test_write_and_load_round_trip_exact_to_float32(tmp_path):
    rng = np.random.default_rng(0)
    mesh = Mesh(rng.normal(0, 0.1, (7, 3)), rng.uniform(0, 1, (7, 2)), np.array([[0, 1, 2], [2, 3, 4], [4, 5, 6]]))
    texture = rng.integers(0, 256, (8, 6, 3), dtype=np.uint8)
    names = write_scan(tmp_path / "Mug", mesh, _png(texture))
    assert names == ("Mug.npz", "Mug.png")
    scan = load_scan(tmp_path, "Mug", *names)
    assert scan.name == "Mug"
    assert np.array_equal(scan.mesh.vertices, mesh.vertices.astype(np.float32).astype(np.float64))
    assert np.array_equal(scan.mesh.uvs, mesh.uvs.astype(np.float32).astype(np.float64))
    assert not np.array_equal(scan.mesh.vertices, mesh.vertices)  # float32, not the float64 written
    assert np.array_equal(scan.mesh.faces, mesh.faces) and scan.mesh.faces.dtype == np.int64
    assert np.array_equal(scan.texture, texture)


def test_the_same_mesh_written_twice_gives_the_same_bytes(tmp_path, monkeypatch):
    """The archive's entries carry a fixed date, so a prepared scan folder does not change with the clock."""
    import time

    mesh = Mesh(np.eye(3), np.zeros((3, 2)), np.array([[0, 1, 2]]))
    write_scan(tmp_path / "a" / "Mug", mesh, _png(np.zeros((2, 2, 3), np.uint8)))
    later = time.time() + 3 * 24 * 3600  # three days on: np.savez_compressed would stamp another date
    monkeypatch.setattr(time, "time", lambda: later)
    monkeypatch.setattr(time, "localtime", lambda *_: time.gmtime(later))
    write_scan(tmp_path / "b" / "Mug", mesh, _png(np.zeros((2, 2, 3), np.uint8)))
    assert (tmp_path / "a" / "Mug.npz").read_bytes() == (tmp_path / "b" / "Mug.npz").read_bytes()


def test_damaged_mesh_files_name_the_file(tmp_path):
    mesh = read_obj(QUAD_OBJ)
    names = write_scan(tmp_path / "Mug", mesh, _png(np.zeros((4, 4, 3), np.uint8)))
    data = (tmp_path / "Mug.npz").read_bytes()
    (tmp_path / "Mug.npz").write_bytes(data[:len(data) // 2])
    with pytest.raises(ScanError, match=rf"^{at(tmp_path / 'Mug.npz')}: not a scan mesh"):
        load_scan(tmp_path, "Mug", *names)
    with pytest.raises(ScanError, match=rf"^{at(tmp_path / 'Gone.npz')}: not a scan mesh"):
        load_scan(tmp_path, "Gone", "Gone.npz", "Mug.png")
    np.savez(tmp_path / "Bad.npz", vertices=mesh.vertices, uvs=mesh.uvs, faces=mesh.faces + 10)
    with pytest.raises(ScanError, match=rf"^{at(tmp_path / 'Bad.npz')}: not a scan mesh \(vertices \(5, 3\)"):
        load_scan(tmp_path, "Bad", "Bad.npz", "Mug.png")


# ---------------------------------------------------------------- scan folders
def _folder(tmp_path, families: list[tuple[str, str, str, str]], scans=("A", "B")):
    root = tmp_path / "scans"
    root.mkdir()
    for name in scans:
        write_scan(root / "scans" / name, read_obj(QUAD_OBJ), _png(np.full((4, 4, 3), 200, np.uint8)))
    with (root / "scans.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["scan", "mesh", "texture", "source", "licence"])
        w.writerows([[n, f"scans/{n}.npz", f"scans/{n}.png", f"here:{n}", "CC0"] for n in scans])
    with (root / "families.csv").open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["family", "scan", "split", "difference"])
        w.writerows(families)
    return root


def test_a_valid_folder_opens_and_loads(tmp_path):
    root = _folder(tmp_path, [("mug", "A", "train", "print"), ("mug", "B", "val", "colour")])
    folder = ScanFolder.open(root)
    assert [(m.family, m.scan, m.split, m.difference) for m in folder.members] == [
        ("mug", "A", "train", "print"), ("mug", "B", "val", "colour")]
    assert folder.scans["B"]["source"] == "here:B"
    assert len(folder.load("B").mesh.faces) == 3


@pytest.mark.parametrize("families, message", [
    ([("mug", "A", "train", "print"), ("mug", "C", "val", "print")], r"scan 'C' is not in .*scans\.csv"),
    ([("mug", "A", "train", "print"), ("cup", "A", "val", "print")], r"scan 'A' is listed twice"),
    ([("mug", "A", "test", "print")], r"scan 'A': split must be train or val .* got 'test' and 'print'"),
    ([("mug", "A", "train", "size")], r"scan 'A': split must be train or val .* got 'train' and 'size'"),
])
def test_folder_errors_name_the_file(tmp_path, families, message):
    root = _folder(tmp_path, families)
    with pytest.raises(ScanError, match=rf"^{at(root / 'families.csv')}: {message}"):
        ScanFolder.open(root)


def test_a_folder_without_its_tables_names_them(tmp_path):
    root = _folder(tmp_path, [("mug", "A", "train", "print")])
    (root / "families.csv").write_text("family,scan\nmug,A\n", encoding="utf-8")
    with pytest.raises(ScanError, match=rf"^{at(root / 'families.csv')} needs a header with \['family', 'scan', "):
        ScanFolder.open(root)
    (root / "scans.csv").unlink()
    with pytest.raises(ScanError, match=rf"cannot read {at(root / 'scans.csv')}"):
        ScanFolder.open(root)


# ---------------------------------------------------------------- the folder shipped with pin_match
def test_the_shipped_folder_opens_whole():
    folder = ScanFolder.open()
    assert folder.root == PACKAGED_SCANS
    assert len(folder.members) == 96 and len({m.family for m in folder.members}) == 17
    assert {m.scan for m in folder.members} == set(folder.scans)
    for name, row in folder.scans.items():
        assert (PACKAGED_SCANS / row["mesh"]).is_file() and (PACKAGED_SCANS / row["texture"]).is_file(), name
        assert row["source"] == f"github:vikashplus/object_sim@f84875d:google_objects/{name}"
        assert row["licence"].startswith("CC BY 4.0")
    notice = (PACKAGED_SCANS / "NOTICE.md").read_text(encoding="utf-8")
    assert "CC BY 4.0" in notice and "96 scans" in notice
    missing = [name for name in folder.scans if f"- `{name}`: {folder.scans[name]['source']}" not in notice]
    assert missing == []


def test_the_shipped_families_are_what_the_docs_and_the_default_size_say():
    """docs/synthetic.md and SynthSize's docstring count the splits: 51 / 45 instances, 15 families each."""
    from collections import Counter

    from pin_match.data.synth import SynthSize

    members = ScanFolder.open().members
    per_split = Counter(m.split for m in members)
    families = {split: Counter(m.family for m in members if m.split == split) for split in ("train", "val")}
    with_lookalike = {split: {f for f, n in counted.items() if n >= 2} for split, counted in families.items()}
    every = {m.family for m in members}
    assert (per_split["train"], per_split["val"]) == (51, 45)
    assert {split: sorted(every - found) for split, found in with_lookalike.items()} == \
        dict(train=["file sorter", "mug"], val=["portable drive", "shoes"])
    assert SynthSize().episodes // 2 == len(with_lookalike["val"]) == len(with_lookalike["train"]) == 15
    kinds = {kind: {m.family for m in members if m.split == "val" and m.difference == kind}
             for kind in ("print", "colour", "shape")}
    assert {kind: len(found) for kind, found in kinds.items()} == dict(print=7, colour=5, shape=4)
    doc = (Path(__file__).resolve().parents[1] / "docs" / "synthetic.md").read_text(encoding="utf-8")
    assert "51 train and 45 val instances" in doc and "(51 train / 45 val instances by default)" in doc
    assert "7 print families, 5 with colour differences, 4 with shape" in doc


def test_every_shipped_scan_loads_and_stands_on_the_floor():
    folder = ScanFolder.open()
    for name in folder.scans:
        scan = folder.load(name)
        lo, hi = scan.mesh.bounds
        assert lo[2] == pytest.approx(0, abs=1e-6) and np.allclose((lo[:2] + hi[:2]) / 2, 0, atol=1e-6), name
        assert 0.01 < hi[2] < 1.0 and scan.texture.ndim == 3 and scan.texture.shape[2] == 3, name


def test_a_copied_folder_with_a_damaged_scan_names_it(tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(PACKAGED_SCANS, root)
    folder = ScanFolder.open(root)
    name = folder.members[0].scan
    (root / folder.scans[name]["mesh"]).write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(ScanError, match=rf"{at(root / folder.scans[name]['mesh'])}: not a scan mesh"):
        folder.load(name)
