"""The data-source catalogue: every source module registered, requests checked once, one image reader."""

from __future__ import annotations

import ast
from pathlib import Path

import cv2
import numpy as np
import pytest

from pin_match.cli.main import main
from pin_match.data import sources
from pin_match.data.images import ImageFileError, read_image, read_label_png, read_object_mask
from pin_match.data.sources import DataSource, DataSourceError, get, names, register

SOURCES_DIR = Path(sources.__file__).parent


def _registering_modules() -> set[str]:
    """The modules of data/sources/ whose text calls register(...): each must be imported by the package."""
    out = set()
    for path in SOURCES_DIR.glob("*.py"):
        tree = ast.parse(path.read_text())
        calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "register"]
        if calls and path.stem != "catalogue":
            out.add(path.stem)
    return out


def test_every_source_module_is_registered_by_importing_the_package():
    assert _registering_modules() == {m.__name__.rsplit(".", 1)[1] for m in sources.BUILT_IN}
    assert names() == ["core50", "grocery", "gso", "myvlm", "recolour", "synthetic", "twins"]
    for name in names():
        s = get(name)
        assert s.name == name and s.licence and s.variants
        assert bool(s.prepare_inputs) == (s.make_source is not None), name


def test_a_second_source_under_a_known_name_is_refused():
    core50 = get("core50")
    assert register(core50) is core50  # the same entry again is harmless
    with pytest.raises(DataSourceError, match="'core50' is already registered"):
        register(DataSource("core50", "x", "CC0", ("a",), make=lambda *a, **k: None))


def test_requests_a_source_cannot_serve_fail_before_anything_is_written(tmp_path):
    with pytest.raises(DataSourceError, match=r"unknown data source 'nope'; known: core50, grocery"):
        get("nope")
    with pytest.raises(DataSourceError, match=r"no variant 'drawn'; choose one of \['shot', 'pasted'"):
        get("core50").build(tmp_path / "a", "drawn")
    with pytest.raises(DataSourceError, match="pin-match data prepare myvlm MYVLM_REPO --out SRC"):
        get("myvlm").build(tmp_path / "a")
    with pytest.raises(DataSourceError, match="pin-match data prepare gso CHECKOUT --out SRC"):
        get("gso").build(tmp_path / "a")
    with pytest.raises(DataSourceError, match="reads no source folder"):
        get("recolour").build(tmp_path / "a", src=tmp_path)
    with pytest.raises(DataSourceError, match=r"reads 2 input\(s\) \(CORE50_REPO ROOMS_REPO\), got 1"):
        get("core50").prepare([tmp_path], tmp_path / "src")
    with pytest.raises(DataSourceError, match="needs no preparing"):
        get("synthetic").prepare([], tmp_path / "src")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_the_command_line_lists_every_source_with_its_licence(capsys):
    assert main(["data", "list"]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert [r.split()[0] for r in rows] == names()
    assert main(["data", "list", "--verbose"]) == 0
    assert "licence: CC BY 4.0 (CORe50" in capsys.readouterr().out


def test_one_reader_names_the_file_in_every_failure(tmp_path):
    photo = np.zeros((6, 8, 3), np.uint8)
    photo[..., 0] = 200  # red
    cv2.imwrite(str(tmp_path / "p.png"), photo[..., ::-1])
    assert read_image(tmp_path / "p.png")[0, 0].tolist() == [200, 0, 0]
    with pytest.raises(ImageFileError, match=r"p\.png has no alpha channel"):
        read_image(tmp_path / "p.png", rgba=True)
    (tmp_path / "bad.jpg").write_bytes(b"not a jpeg")
    with pytest.raises(ImageFileError, match=r"corrupt or unreadable image .*bad\.jpg"):
        read_image(tmp_path / "bad.jpg")
    with pytest.raises(ImageFileError, match=r"missing or empty file .*nowhere\.png"):
        read_label_png(tmp_path / "nowhere.png")
    mask = np.zeros((6, 8), np.uint8)
    mask[2:4, 2:5] = 255
    cv2.imwrite(str(tmp_path / "m.png"), mask)
    assert read_object_mask(tmp_path / "m.png", (6, 8)).sum() == 6
    with pytest.raises(ImageFileError, match=r"m\.png is missing, unreadable or not the size of its photo \(5, 8\)"):
        read_object_mask(tmp_path / "m.png", (5, 8))
    cv2.imwrite(str(tmp_path / "empty.png"), np.zeros((6, 8), np.uint8))
    with pytest.raises(ImageFileError, match=r"mask .*empty\.png is empty"):
        read_object_mask(tmp_path / "empty.png", (6, 8))
