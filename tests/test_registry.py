"""The registry finds built-ins by name, plugs in a toy matcher of the tests, and explains mistakes."""

from __future__ import annotations

import importlib
import pkgutil
import re
import sys
import textwrap
import types
from importlib.metadata import EntryPoint

import numpy as np
import pytest
from toys import BrightMatcher, HandSet

from pin_match import MatchResult, create_matcher, list_matchers, register_matcher
from pin_match.contract import registry
from pin_match.contract.matcher import ConfigError, MatcherError
from pin_match.contract.registry import UnknownMatcherError, parse_overrides
from pin_match.contract.scan import RegistrationError, scan_package


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
    for name in ("sift", "color"):
        sys.modules.pop(f"pin_match.matchers.{name}", None)  # the module is named after its matcher
        registry._REGISTRY.pop(name, None)
        assert create_matcher(name).name == name
    assert {"sift", "color", "dino", "dinov2", "clip", "clip-text", "superglue", "owl", "persam"} <= \
        set(list_matchers())
    assert list_matchers("clip*") == sorted(n for n in list_matchers() if n.startswith("clip"))


def test_the_listed_built_ins_are_exactly_what_their_modules_register():
    """Every module of the built-in package imported: what they register is what the scan listed, both ways."""
    package = importlib.import_module(registry.BUILTIN_PACKAGE)
    for info in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"{registry.BUILTIN_PACKAGE}.{info.name}")
    registered = {name: cls.__module__ for name, cls in registry._REGISTRY.items()
                  if cls.__module__.startswith(f"{registry.BUILTIN_PACKAGE}.")}
    assert registered == registry.builtin_modules()
    assert {n: f"{c.__module__}.{c.__qualname__}" for n, c in registry._REGISTRY.items() if n in registered} == \
        {n: r.dotted for n, r in registry.builtin_registrations().items()}
    assert {"sift", "color", "effnet", "superglue", "ieve", "xfeat", "fusion", "learned"} <= set(registered)


@pytest.fixture
def scan(tmp_path, monkeypatch):
    """Writes files into a package of its own and reads it as the registry reads the built-in folder."""
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "toy_builtins").mkdir()
    (tmp_path / "toy_builtins" / "__init__.py").write_text("")

    def write_and_scan(files: dict[str, str]) -> dict:
        for name, text in files.items():
            path = tmp_path / "toy_builtins" / name
            path.parent.mkdir(exist_ok=True)
            path.write_text(textwrap.dedent(text))
        scan_package.cache_clear()
        try:
            return scan_package("toy_builtins")
        finally:
            scan_package.cache_clear()

    write_and_scan.folder = tmp_path / "toy_builtins"
    return write_and_scan


def test_a_new_file_with_the_decorator_is_all_a_built_in_needs(scan, monkeypatch):
    """The built-in folder stood in for by a package of the test's own, so the checkout is never written."""
    monkeypatch.setattr(registry, "BUILTIN_PACKAGE", "toy_builtins")
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    scan({"brand_new.py": """
        from pin_match.contract import MatchResult, Matcher, register_matcher

        @register_matcher("brand-new")
        class BrandNew(Matcher):
            def _prepare(self, target):
                pass

            def _match_batch(self, images):
                return [MatchResult(score=0.25) for _ in images]
    """})
    try:
        assert list_matchers("brand-*") == ["brand-new"]
        assert "toy_builtins.brand_new" not in sys.modules  # listed without importing it
        assert create_matcher("brand-new").default_sigma == 0.5
    finally:
        scan_package.cache_clear()
        sys.modules.pop("toy_builtins.brand_new", None)
        sys.modules.pop("toy_builtins", None)


@pytest.mark.parametrize("package, why", [("no_such_matchers_package", "not installed"),
                                          ("no_such_parent.matchers", "not installed"),
                                          ("json.decoder", "a module, not a package")])
def test_the_scan_of_a_package_it_cannot_read_names_the_package(package, why):
    """Issue 43.3c: the scan once returned no names at all, so a missing built-in package listed no matchers."""
    scan_package.cache_clear()
    try:
        with pytest.raises(RegistrationError, match=rf"{re.escape(package)}.*{why}"):
            scan_package(package)
    finally:
        scan_package.cache_clear()


def test_the_scan_reads_literal_decorators_and_ignores_mere_mentions(scan):
    found = scan({"a.py": """
        \"\"\"Mentions register_matcher in prose only.\"\"\"
        from pin_match import contract
        from pin_match.contract import register_matcher

        @register_matcher("toy-a")
        class A:
            pass

        @contract.register_matcher("toy-b")
        class B:
            pass
    """})
    assert {n: (r.module, r.qualname, r.line) for n, r in found.items()} == \
        {"toy-a": ("toy_builtins.a", "A", 6), "toy-b": ("toy_builtins.a", "B", 10)}


NAME_IN_A_VARIABLE = """
    from pin_match.contract import register_matcher
    NAME = "toy-a"

    @register_matcher(NAME)
    class A:
        pass
"""
PLAIN_CALL = """
    from pin_match.contract import register_matcher

    class A:
        pass

    register_matcher("toy-a")(A)
"""
ALIAS = """
    from pin_match.contract import register_matcher as rm

    @rm("toy-a")
    class A:
        pass
"""
IN_A_FUNCTION = """
    from pin_match.contract import register_matcher

    def make():
        @register_matcher("toy-a")
        class A:
            pass
        return A
"""
DECORATED = """
    from pin_match.contract import register_matcher

    @register_matcher("toy-a")
    class A:
        pass
"""


@pytest.mark.parametrize("files, where, message", [
    ({"a.py": NAME_IN_A_VARIABLE}, "a.py:5", "register_matcher used in a way the registry cannot read"),
    ({"a.py": PLAIN_CALL}, "a.py:7", "register_matcher used in a way the registry cannot read"),
    ({"a.py": ALIAS}, "a.py:2", "register_matcher used in a way the registry cannot read"),
    ({"a.py": IN_A_FUNCTION}, "a.py:5", "register_matcher used in a way the registry cannot read"),
    ({"sub/a.py": DECORATED}, "sub/a.py:4", "register_matcher in a subfolder of toy_builtins is never read"),
    ({"a.py": DECORATED, "b.py": DECORATED}, "b.py:4", "matcher name 'toy-a' is already registered at .*a.py:4"),
])
def test_the_scan_refuses_what_it_cannot_read_naming_file_and_line(scan, files, where, message):
    with pytest.raises(RegistrationError) as err:
        scan(files)
    text = str(err.value)
    assert "\n" not in text and text.startswith(f"{scan.folder}/{where}: ")
    assert re.search(message, text), text


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


def test_a_name_belongs_to_one_module_and_class(monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    _module_defining("toy_first", "test-one-owner")
    again = _module_defining("toy_first", "test-one-owner")  # the same module imported anew
    assert registry._REGISTRY["test-one-owner"] is again.Toy
    with pytest.raises(RegistrationError, match=r"^matcher name 'test-one-owner' is already registered by "
                                                r"toy_first\.Toy; toy_second\.Toy needs another name$"):
        _module_defining("toy_second", "test-one-owner")  # same class name, another module


def test_a_plug_in_cannot_take_a_built_ins_name_even_before_it_is_imported(monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", {})
    sift = registry.builtin_registrations()["sift"]
    with pytest.raises(RegistrationError, match=f"'sift' is already registered by {re.escape(sift.dotted)}; "
                                                f"toy_plugin.Toy needs another name"):
        _module_defining("toy_plugin", "sift")
    assert registry._REGISTRY == {}


def _entry_point(name: str, value: str) -> EntryPoint:
    return EntryPoint(name=name, value=value, group=registry.ENTRY_POINT_GROUP)


def test_an_entry_point_cannot_take_a_name_another_class_holds(monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    sift = registry.builtin_registrations()["sift"]
    clash = _entry_point("sift", "toys:BrightMatcher")
    monkeypatch.setattr(registry, "_entry_points", lambda: {"sift": clash})
    expected = f"'sift' is already registered by {re.escape(sift.dotted)}; toys.BrightMatcher needs"
    with pytest.raises(RegistrationError, match=expected):
        list_matchers()
    registry._REGISTRY.pop("sift", None)
    with pytest.raises(RegistrationError, match=expected):
        create_matcher("sift")
    # the same class under its own name again, declared by its package, is no clash
    monkeypatch.setattr(registry, "_entry_points",
                        lambda: {"test-bright": _entry_point("test-bright", "toys:BrightMatcher")})
    assert create_matcher("test-bright").default_sigma == 100.0


def test_two_entry_points_cannot_declare_one_name(monkeypatch):
    declared = [_entry_point("toy-twice", "pkg_a:Toy"), _entry_point("toy-twice", "pkg_b:Toy")]
    monkeypatch.setattr(registry, "entry_points", lambda group: declared)
    with pytest.raises(RegistrationError, match=r"^matcher name 'toy-twice' is declared by two entry points, "
                                                r"pkg_a:Toy and pkg_b:Toy; uninstall one of their packages$"):
        list_matchers()


def test_entry_point_matchers_are_found(monkeypatch):
    ep = EntryPoint(name="third-party", value="toys:BrightMatcher", group=registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "_entry_points", lambda: {"third-party": ep})
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    registry._REGISTRY.pop("third-party", None)
    assert "third-party" in list_matchers()
    assert create_matcher("third-party").default_sigma == 100.0


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
