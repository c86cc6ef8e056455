"""The registry finds built-ins by name, plugs in a matcher defined right here, and explains mistakes."""

from __future__ import annotations

import importlib
import os
import sys
import textwrap
from dataclasses import dataclass
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest

from pin_match import (
    Matcher,
    MatcherConfig,
    MatchResult,
    Modality,
    create_matcher,
    list_matchers,
    register_matcher,
)
from pin_match.contract import registry
from pin_match.contract.matcher import ConfigError, MatcherError
from pin_match.contract.registry import UnknownMatcherError, parse_overrides


@dataclass
class BrightConfig(MatcherConfig):
    gain: float = 1.0
    channels: tuple[int, ...] = (0, 1, 2)
    verbose: bool = False


@register_matcher("test-bright")
class BrightMatcher(Matcher):
    """Scores an image by its brightest pixel; the point is that pixel."""

    Config = BrightConfig
    modality = Modality.VISUAL
    default_sigma = 100.0

    def _prepare(self, target):
        self.prepared_with = target

    def _match_batch(self, images):
        out = []
        for im in images:
            lum = im[..., list(self.cfg.channels)].astype(float).mean(-1) * self.cfg.gain
            y, x = np.unravel_index(np.argmax(lum), lum.shape)
            out.append(MatchResult(score=float(lum.max()), points=[[x, y]]))
        return out


def test_plugin_defined_in_a_test_file_plugs_in(tiny_frameset):
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
        sys.modules.pop("pin_match.matchers.classic", None)
        registry._REGISTRY.pop(name, None)
        assert create_matcher(name).name == name
    assert {"sift", "color", "dino", "dinov2", "clip", "clip-text", "superglue", "owl", "persam"} <= \
        set(list_matchers())
    assert list_matchers("clip*") == sorted(n for n in list_matchers() if n.startswith("clip"))


def test_a_new_file_in_matchers_with_the_decorator_is_all_a_built_in_needs():
    folder = Path(registry.__file__).resolve().parents[2] / "matchers"
    new = folder / f"_new_builtin_{os.getpid()}.py"
    new.write_text(textwrap.dedent("""
        from pin_match.contract import MatchResult, Matcher, register_matcher

        @register_matcher("brand-new")
        class BrandNew(Matcher):
            def _prepare(self, target):
                pass

            def _match_batch(self, images):
                return [MatchResult(score=0.25) for _ in images]
    """))
    registry.modules_registering.cache_clear()
    try:
        assert "brand-new" in list_matchers("brand-*")
        assert f"pin_match.matchers.{new.stem}" not in sys.modules  # listed without importing it
        assert create_matcher("brand-new").default_sigma == 0.5
    finally:
        new.unlink()
        registry.modules_registering.cache_clear()
        registry._REGISTRY.pop("brand-new", None)
        sys.modules.pop(f"pin_match.matchers.{new.stem}", None)
    assert "brand-new" not in list_matchers()


def test_the_listed_built_ins_are_exactly_what_their_modules_register():
    registered = {}
    for name, module in registry.builtin_modules().items():
        importlib.import_module(module)
        registered[name] = registry._REGISTRY[name].__module__
    assert registered == registry.builtin_modules()
    assert {"sift", "color", "effnet", "superglue", "ieve", "xfeat", "fusion", "learned"} <= set(registered)


def test_entry_point_matchers_are_found(monkeypatch):
    ep = EntryPoint(name="third-party", value="test_registry:BrightMatcher", group=registry.ENTRY_POINT_GROUP)
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


class _Broken(Matcher):
    modality = Modality.VISUAL

    def __init__(self, result):
        super().__init__()
        self.result = result

    def _prepare(self, target):
        pass

    def _match_batch(self, images):
        return [self.result for _ in images]


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
    m = _Broken(result)
    m.prepare(tiny_frameset.target("mug_a"))
    with pytest.raises(MatcherError, match=f"matcher _Broken.*{message}|{message}"):
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
