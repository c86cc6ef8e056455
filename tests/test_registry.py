"""The registry finds built-ins by name, plugs in a toy matcher of the tests, and explains mistakes."""

from __future__ import annotations

import importlib
import pkgutil
import re
import subprocess
import sys
import textwrap
import types
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest
from toys import BrightMatcher, HandSet

from pin_match import MatchResult, create_matcher, list_matchers, register_matcher
from pin_match.contract import discovery, registry
from pin_match.contract.matcher import ConfigError, MatcherError
from pin_match.contract.registry import RegistrationError, UnknownMatcherError, parse_overrides


def test_a_plug_in_from_outside_the_package_plugs_in(tiny_frameset):
    assert "test-bright" in list_matchers("test-*")
    m = create_matcher("test-bright", gain="2")
    assert m.cfg.gain == 2.0
    m.prepare(tiny_frameset.target("mug_a"))
    assert m.prepared_with.category == ""  # a visual matcher never sees the category label
    image = np.zeros((20, 30, 3), np.uint8)
    image[5, 7] = 100
    r = m.match(image)
    assert r.score == pytest.approx(200.0 * 1 / 1) and r.points.tolist() == [[7.0, 5.0]]
    assert m.id.startswith("test-bright@") and m.id != create_matcher("test-bright").id


def test_config_coercion_and_errors():
    m = create_matcher("test-bright", channels="0,2", verbose="yes")
    assert m.cfg.channels == (0, 2) and m.cfg.verbose is True
    with pytest.raises(ConfigError, match=r"no config key 'gian'.*did you mean gain"):
        create_matcher("test-bright", gian=2)
    with pytest.raises(ConfigError, match=r"cannot read 'abc'"):
        create_matcher("test-bright", gain="abc")
    with pytest.raises(ConfigError, match=r"crops='diagonal'"):
        create_matcher("color", crops="diagonal")
    # keys a matcher does not use are refused, not hashed into a new id
    with pytest.raises(ConfigError, match=r"matcher 'test-bright' has no config key 'crops'"):
        create_matcher("test-bright", crops="pin")
    with pytest.raises(ConfigError, match=r"matcher 'sift' has no config key 'weights'"):
        create_matcher("sift", weights="/nonexistent")
    with pytest.raises(ConfigError, match="expected key=value"):
        parse_overrides(["gain"])
    assert parse_overrides(["gain=2", "crops = pin"]) == {"gain": "2", "crops": "pin"}


def test_config_hash_ignores_device_but_not_settings():
    base = create_matcher("test-bright")
    assert create_matcher("test-bright", device="cuda").config_hash == base.config_hash
    assert create_matcher("test-bright", gain=3.0).config_hash != base.config_hash


def test_unknown_matcher_suggests_close_names():
    with pytest.raises(UnknownMatcherError, match=r"unknown matcher 'dinov3'.*did you mean.*dinov2"):
        create_matcher("dinov3")


def test_builtins_resolve_without_importing_their_module_first():
    """A fresh process: naming a built-in is enough, whatever was imported before."""
    code = ("import sys; from pin_match import create_matcher, list_matchers; "
            "assert 'pin_match.matchers.sift' not in sys.modules; print(create_matcher('sift').name); "
            "print(' '.join(list_matchers()))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.splitlines()
    assert out[0] == "sift"
    assert {"sift", "color", "dino", "dinov2", "clip", "clip-text", "superglue", "owl", "persam", "verify"} <= \
        set(out[1].split())
    assert list_matchers("clip*") == sorted(n for n in list_matchers() if n.startswith("clip"))


def test_every_module_of_the_built_in_package_is_imported_and_registers():
    """What the built-in package's modules register is what is listed: each listed class lives in one of them."""
    package = importlib.import_module(registry.BUILTIN_PACKAGE)
    modules = {info.name for info in pkgutil.walk_packages(package.__path__, f"{registry.BUILTIN_PACKAGE}.")}
    listed = {name: registry.get_matcher_class(name).__module__ for name in list_matchers()}
    built_in = {name: module for name, module in listed.items() if module.startswith(f"{registry.BUILTIN_PACKAGE}.")}
    assert modules <= set(sys.modules) and set(built_in.values()) <= modules
    assert {"sift", "color", "effnet", "superglue", "ieve", "xfeat", "fusion", "learned", "verify"} <= set(built_in)


@pytest.fixture
def toy_builtins(tmp_path, monkeypatch):
    """A package of the test's own stands in for the built-in folder, so the checkout is never written."""
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "BUILTIN_PACKAGE", "toy_builtins")
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(discovery, "_IMPORTED", set())
    folder = tmp_path / "toy_builtins"
    folder.mkdir()
    (folder / "__init__.py").write_text("")

    def write(files: dict[str, str]) -> None:
        for name, text in files.items():
            path = folder / name
            path.parent.mkdir(exist_ok=True)
            path.write_text(textwrap.dedent(text))

    yield write
    for module in [m for m in sys.modules if m == "toy_builtins" or m.startswith("toy_builtins.")]:
        del sys.modules[module]


TOY = """
    from pin_match.contract import MatchResult, Matcher, register_matcher as {decorator}

    NAME = {name!r}


    @{decorator}(NAME)
    class {cls}(Matcher):
        def _prepare(self, target):
            pass

        def _match_batch(self, images):
            return [MatchResult(score=0.25) for _ in images]
"""


def test_a_new_file_in_the_built_in_package_is_all_a_built_in_needs(toy_builtins):
    """However the decorator is written (an alias, a name in a variable) and wherever the file is (a subfolder)."""
    toy_builtins({"brand_new.py": TOY.format(decorator="register_matcher", name="brand-new", cls="BrandNew"),
                  "sub/__init__.py": "",
                  "sub/deeper.py": TOY.format(decorator="rm", name="brand-deeper", cls="Deeper")})
    assert list_matchers("brand-*") == ["brand-deeper", "brand-new"]
    assert create_matcher("brand-new").default_sigma == 0.5
    assert registry.get_matcher_class("brand-deeper").__module__ == "toy_builtins.sub.deeper"


def test_a_built_in_module_that_cannot_be_imported_is_named_every_time(toy_builtins):
    toy_builtins({"fine.py": TOY.format(decorator="register_matcher", name="brand-fine", cls="Fine"),
                  "needs_more.py": "import no_such_dependency_of_a_matcher\n"})
    for _ in range(2):  # the failed import is not remembered as done: the next lookup fails the same way
        with pytest.raises(RegistrationError, match=r"^cannot import toy_builtins\.needs_more, a module of the "
                                                    r"built-in matchers \(toy_builtins\): No module named "
                                                    r"'no_such_dependency_of_a_matcher'$"):
            list_matchers()


def test_a_missing_built_in_package_is_named(monkeypatch):
    """Issue 43.3c: a missing built-in package once listed no matchers at all, silently."""
    monkeypatch.setattr(registry, "BUILTIN_PACKAGE", "no_such_matchers_package")
    monkeypatch.setattr(discovery, "_IMPORTED", set())
    with pytest.raises(RegistrationError, match=r"^cannot import no_such_matchers_package, a module of the built-in "
                                                r"matchers \(no_such_matchers_package\)"):
        create_matcher("sift")


def _module_defining(module: str, name: str) -> types.ModuleType:
    """A module named ``module`` whose class ``Toy`` registers ``name``: importing one file twice, or two files."""
    made = types.ModuleType(module)
    exec(textwrap.dedent(f"""
        from pin_match.contract import MatchResult, Matcher, register_matcher

        @register_matcher({name!r})
        class Toy(Matcher):
            def _prepare(self, target):
                pass

            def _match_batch(self, images):
                return [MatchResult(score=0.0) for _ in images]
    """), made.__dict__)
    return made


def test_a_name_belongs_to_one_module_and_class(own_registry):
    _module_defining("toy_first", "test-one-owner")
    again = _module_defining("toy_first", "test-one-owner")  # the same module imported anew
    assert registry._REGISTRY["test-one-owner"] is again.Toy
    with pytest.raises(RegistrationError, match=r"^matcher name 'test-one-owner' is already registered by "
                                                r"toy_first\.Toy; toy_second\.Toy needs another name$"):
        _module_defining("toy_second", "test-one-owner")  # same class name, another module


def _dotted(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def test_a_plug_in_cannot_take_a_built_ins_name(own_registry):
    sift = _dotted(registry.get_matcher_class("sift"))
    with pytest.raises(RegistrationError, match=f"^matcher name 'sift' is already registered by {re.escape(sift)}; "
                                                f"toy_plugin.Toy needs another name$"):
        _module_defining("toy_plugin", "sift")
    assert _dotted(registry.get_matcher_class("sift")) == sift


def test_a_plug_in_imported_before_the_built_ins_with_a_built_ins_name_is_the_one_named(toy_builtins):
    toy_builtins({"brand_new.py": TOY.format(decorator="register_matcher", name="brand-new", cls="BrandNew")})
    _module_defining("toy_plugin", "brand-new")  # the built-ins are not imported yet: nothing to refuse it against
    with pytest.raises(RegistrationError, match=r"^matcher name 'brand-new' belongs to the built-in "
                                                r"toy_builtins\.brand_new\.BrandNew, but toy_plugin\.Toy registered it "
                                                r"first; toy_plugin\.Toy needs another name$"):
        list_matchers()


def _entry_point(name: str, value: str) -> EntryPoint:
    return EntryPoint(name=name, value=value, group=registry.ENTRY_POINT_GROUP)


def test_an_entry_point_cannot_take_a_name_another_class_holds(monkeypatch, own_registry):
    sift = _dotted(registry.get_matcher_class("sift"))
    clash = _entry_point("sift", "toys:BrightMatcher")
    monkeypatch.setattr(registry, "_entry_points", lambda: {"sift": clash})
    with pytest.raises(RegistrationError, match=f"'sift' is already registered by {re.escape(sift)}; "
                                                f"toys.BrightMatcher needs"):
        list_matchers()
    # the same class under its own name again, declared by its package, is no clash
    monkeypatch.setattr(registry, "_entry_points",
                        lambda: {"test-bright": _entry_point("test-bright", "toys:BrightMatcher")})
    assert create_matcher("test-bright").default_sigma == 100.0


def test_two_entry_points_cannot_declare_one_name(monkeypatch):
    declared = [_entry_point("toy-twice", "pkg_a:Toy"), _entry_point("toy-twice", "pkg_b:Toy")]
    monkeypatch.setattr(discovery, "entry_points", lambda group: declared)
    with pytest.raises(RegistrationError, match=r"^matcher name 'toy-twice' is declared by two entry points, "
                                                r"pkg_a:Toy and pkg_b:Toy; uninstall one of their packages$"):
        list_matchers()


def test_entry_point_matchers_are_found(monkeypatch, own_registry):
    ep = EntryPoint(name="third-party", value="toys:BrightMatcher", group=registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "_entry_points", lambda: {"third-party": ep})
    assert "third-party" in list_matchers()
    assert create_matcher("third-party").default_sigma == 100.0


@pytest.mark.parametrize("value, message", [
    ("toy_nowhere:Toy", r"cannot be loaded: ModuleNotFoundError: No module named 'toy_nowhere'$"),
    ("toys:NO_SUCH_CLASS", r"cannot be loaded: AttributeError: .*NO_SUCH_CLASS"),
    ("pin_match:__version__", r"names a str, not a Matcher subclass$"),
    ("pin_match.contract.matcher:Target", r"names pin_match\.contract\.matcher\.Target, not a Matcher subclass$"),
])
def test_a_broken_entry_point_is_named_as_a_data_sources_is(monkeypatch, own_registry, value, message):
    """One loader for matchers and data sources (discovery.load): the same words, the matcher's error type."""
    monkeypatch.setattr(registry, "_entry_points", lambda: {"toy-broken": _entry_point("toy-broken", value)})
    with pytest.raises(RegistrationError, match=rf"^matcher entry point 'toy-broken' \({re.escape(value)}, group "
                                                rf"pin_match\.matchers\) {message}"):
        create_matcher("toy-broken")


def test_every_package_folder_is_in_the_wheel():
    """discovery imports the modules of subpackages too, but an installed wheel holds a subfolder only where
    pyproject.toml lists it: every folder of pin_match/ and matchers/ with modules is a listed package."""
    import tomllib

    root = Path(__file__).resolve().parents[1]
    setuptools = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    tops = {"pin_match": root / "pin_match", **{name: root / folder
                                                for name, folder in setuptools["package-dir"].items()}}
    found = set()
    for name, top in tops.items():
        for folder in [top, *(d for d in top.rglob("*") if d.is_dir() and d.name != "__pycache__")]:
            if any(folder.glob("*.py")):
                assert (folder / "__init__.py").is_file(), f"{folder} holds modules but no __init__.py"
                found.add(".".join((name, *folder.relative_to(top).parts)))
    assert found == set(setuptools["packages"])


def test_register_rejects_non_matchers_and_clashes():
    with pytest.raises(TypeError):
        register_matcher("x")(object)

    class Other(BrightMatcher):
        pass

    with pytest.raises(ValueError, match="already registered"):
        register_matcher("test-bright")(Other)


@pytest.mark.parametrize("result, message", [
    (MatchResult(score=float("nan")), "non-finite score"),
    (MatchResult(score=float("inf")), "non-finite score"),
    (MatchResult(score=1.0, points=[[40.0, 1.0]]), "outside the 30x20 image"),
    (MatchResult(score=1.0, points=[[1.0, -1.0]]), "outside"),
    (MatchResult(score=1.0, points=[[1.0, 1.0]], point_scores=[1.0, 2.0]), "2 point scores for 1 points"),
    (MatchResult(score=1.0, points=[[1.0, 1.0]], point_scores=[np.nan]), "non-finite point scores"),
    (MatchResult(score=1.0, box_views=[0]), r"box views that are not one view index \(0-2\) per box"),
    (MatchResult(score=1.0, boxes=[[0, 0, 4, 4]], box_scores=[1.0], box_views=[3]), "not one view index"),
    (MatchResult(score=1.0, boxes=[[0, 0, 4, 4]], box_scores=[1.0], box_views=[0, 1]), "not one view index"),
    (MatchResult(score=1.0, boxes=[[0, 0, 4, 4]], box_scores=[1.0], box_views=[0.5]), "not one view index"),
    ("not a result", "returned str"),
])
def test_base_class_rejects_invalid_results_by_name(tiny_frameset, result, message):
    m = HandSet(result)
    m.prepare(tiny_frameset.target("mug_a"))
    with pytest.raises(MatcherError, match=f"matcher hand-set.*{message}"):
        m.match(np.zeros((20, 30, 3), np.uint8))


def test_match_before_prepare_and_bad_images(tiny_frameset):
    m = create_matcher("test-bright")
    with pytest.raises(MatcherError, match="call prepare"):
        m.match(np.zeros((20, 30, 3), np.uint8))
    m.prepare(tiny_frameset.target("mug_a"))
    with pytest.raises(MatcherError, match=r"image 0 must be H x W x 3 uint8"):
        m.match(np.zeros((20, 30, 3), np.float32))
    gray = np.zeros((20, 30), np.uint8)
    gray[3, 4] = 50
    assert m.match(gray).points.tolist() == [[4.0, 3.0]]  # grayscale frames are accepted


def test_points_at_recomputes_for_any_sigma():
    r = MatchResult(score=0.9, points=[[1, 1], [2, 2], [3, 3]], point_scores=[0.9, 0.5, 0.2])
    assert r.points_at(0.95).shape == (0, 2)
    assert r.points_at(0.5).tolist() == [[1, 1], [2, 2]]
    assert r.points_at(0.1).shape == (3, 2)
