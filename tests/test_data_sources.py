"""The data-source catalogue: every source module registered, requests checked once, one image reader."""

from __future__ import annotations

import ast
import importlib
import re
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from pin_match.cli.main import main
from pin_match.contract import discovery
from pin_match.data import sources
from pin_match.data.images import ImageFileError, read_image, read_label_png, read_object_mask
from pin_match.data.sources import DataSource, DataSourceError, catalogue, get, names, register

SOURCES_DIR = Path(sources.__file__).parent
# the sources this file knows of; one added later is reported (a skip naming it), never a failure
KNOWN = ["core50", "grocery", "gso", "myvlm", "recolour", "twins"]


def _registering_modules() -> set[str]:
    """The modules of data/sources/ whose text calls register(...)."""
    out = set()
    for path in SOURCES_DIR.glob("*.py"):
        tree = ast.parse(path.read_text())
        calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "register"]
        if calls and path.stem != "catalogue":
            out.add(path.stem)
    return out


def test_every_source_module_registers_its_source_in_the_catalogue():
    registering = _registering_modules()
    assert len(registering) >= len(KNOWN)
    for stem in registering:
        source = importlib.import_module(f"pin_match.data.sources.{stem}").SOURCE
        assert get(source.name) is source, stem
    for name in names():
        s = get(name)
        assert s.name == name and s.licence and s.variants
        assert bool(s.prepare_inputs) == (s.make_source is not None), name


def test_every_known_source_is_listed_and_a_new_one_is_reported():
    missing = sorted(set(KNOWN) - set(names()))
    assert not missing, f"sources KNOWN names that the catalogue does not list: {missing}"
    new = sorted(set(names()) - set(KNOWN))
    if new:
        pytest.skip("; ".join(f"data source {n!r} is not in KNOWN: add it to tests/test_data_sources.py's KNOWN"
                              for n in new))


@pytest.fixture
def own_catalogue(monkeypatch):
    """The catalogue, built-ins imported, as a copy the test may change: its sources are gone after it."""
    names()
    monkeypatch.setattr(catalogue, "_CATALOGUE", dict(catalogue._CATALOGUE))


TOY_SOURCE = """
from pin_match.data.sources import DataSource, register

SOURCE = DataSource("{name}", "a toy source", "CC0", ("default",), make=lambda out, **kwargs: f"built {{out.name}}")
{register}NOT_A_SOURCE = "just text"
"""


def _distribution(root: Path, package: str, entries: dict[str, str]) -> None:
    """An installed distribution on ``root`` (a folder on sys.path) that declares ``entries`` as data sources."""
    info = root / f"{package}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {package}\nVersion: 0.1\n")
    lines = "".join(f"{name} = {value}\n" for name, value in entries.items())
    (info / "entry_points.txt").write_text(f"[{catalogue.ENTRY_POINT_GROUP}]\n{lines}")


@pytest.fixture
def site(tmp_path, monkeypatch, own_catalogue):
    """A folder on sys.path for third-party distributions; the modules they bring are forgotten after the test."""
    monkeypatch.syspath_prepend(str(tmp_path))
    before = set(sys.modules)
    yield tmp_path
    for module in set(sys.modules) - before:
        if module.startswith("toy_source"):
            del sys.modules[module]


def test_a_third_party_source_is_found_through_its_entry_point_and_loaded_when_asked(site, capsys):
    (site / "toy_source_pkg.py").write_text(TOY_SOURCE.format(name="toy-ep", register=""))
    _distribution(site, "toy_source_pkg", {"toy-ep": "toy_source_pkg:SOURCE"})
    assert "toy-ep" in names()
    assert "toy_source_pkg" not in sys.modules  # listed, not imported
    assert get("toy-ep").build(site / "out") == "built out"
    assert get("toy-ep") is sys.modules["toy_source_pkg"].SOURCE
    assert main(["data", "list"]) == 0
    assert "toy-ep" in [row.split()[0] for row in capsys.readouterr().out.splitlines()]


def test_an_entry_point_may_name_a_source_its_module_registers(site):
    (site / "toy_source_self.py").write_text(TOY_SOURCE.format(name="toy-self", register="register(SOURCE)\n"))
    _distribution(site, "toy_source_self", {"toy-self": "toy_source_self:SOURCE"})
    assert get("toy-self").summary == "a toy source"


@pytest.mark.parametrize("value, message", [
    ("toy_source_nowhere:SOURCE", r"cannot be loaded: ModuleNotFoundError: No module named 'toy_source_nowhere'"),
    ("toy_source_bad:MISSING", r"cannot be loaded: AttributeError: .*MISSING"),
    ("toy_source_bad:NOT_A_SOURCE", r"names a str, not a DataSource$"),
    ("toy_source_bad:SOURCE", r"names the source 'toy-other'; the entry point's name must be the source's$"),
])
def test_a_broken_entry_point_is_named(site, value, message):
    (site / "toy_source_bad.py").write_text(TOY_SOURCE.format(name="toy-other", register=""))
    _distribution(site, "toy_source_bad", {"toy-broken": value})
    assert "toy-broken" in names()
    with pytest.raises(DataSourceError, match=rf"^data source entry point 'toy-broken' \({re.escape(value)}, group "
                                              rf"pin_match\.data_sources\) {message}"):
        get("toy-broken")


def test_two_entry_points_cannot_declare_one_source(site):
    _distribution(site, "toy_source_a", {"toy-twice": "toy_source_a:SOURCE"})
    _distribution(site, "toy_source_b", {"toy-twice": "toy_source_b:SOURCE"})
    with pytest.raises(DataSourceError, match=r"^data source 'toy-twice' is declared by two entry points, "
                                              r"toy_source_\w:SOURCE and toy_source_\w:SOURCE; uninstall one"):
        names()


def test_an_entry_point_cannot_take_a_built_in_sources_name(site):
    (site / "toy_source_clash.py").write_text(TOY_SOURCE.format(name="core50", register=""))
    _distribution(site, "toy_source_clash", {"core50": "toy_source_clash:SOURCE"})
    with pytest.raises(DataSourceError, match=r"^data source entry point 'core50' \(toy_source_clash:SOURCE, .*\): "
                                              r"data source 'core50' is already registered \(by "
                                              r"pin_match\.data\.sources\.core50\); give it another name$"):
        names()


def test_a_new_module_in_the_built_in_package_is_all_a_built_in_source_needs(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(catalogue, "BUILTIN_PACKAGE", "toy_source_builtins")
    monkeypatch.setattr(discovery, "_IMPORTED", set())
    monkeypatch.setattr(catalogue, "_CATALOGUE", {})
    (tmp_path / "toy_source_builtins").mkdir()
    (tmp_path / "toy_source_builtins" / "__init__.py").write_text("")
    (tmp_path / "toy_source_builtins" / "brand_new.py").write_text(
        TOY_SOURCE.format(name="brand-new", register="register(SOURCE)\n"))
    try:
        assert names() == ["brand-new"]
    finally:
        for module in [m for m in sys.modules if m.startswith("toy_source_builtins")]:
            del sys.modules[module]


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
    with pytest.raises(DataSourceError, match="reads no source folder"):
        get("recolour").build(tmp_path / "a", src=tmp_path)
    with pytest.raises(DataSourceError, match=r"reads 2 input\(s\) \(CORE50_REPO ROOMS_REPO\), got 1"):
        get("core50").prepare([tmp_path], tmp_path / "src")
    with pytest.raises(DataSourceError, match="needs no preparing"):
        get("recolour").prepare([], tmp_path / "src")
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
