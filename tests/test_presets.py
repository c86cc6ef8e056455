"""Named variants as presets (contract.Preset): a ``preset=`` class sets config defaults and class data."""

from __future__ import annotations

import dataclasses
import pickle
from dataclasses import dataclass, field

import numpy as np
import pytest
from toys import BrightConfig, BrightMatcher

from pin_match.contract import ConfigError, MatcherConfig, Preset, Target, create_matcher, get_matcher_class
from pin_match.matchers.dino import DINO_PRESETS
from pin_match.matchers.effnet import EFFNET_PRESETS, EffnetMatcher


class BrightDouble(BrightMatcher, preset=Preset(config={"gain": 2.0}, default_sigma=200.0, paper="a toy")):
    """``test-bright`` at twice the gain."""


@dataclass
class LevelConfig(MatcherConfig):
    level: int = field(default=1, metadata={"hash": False, "help": "how loud"})


class Level(BrightMatcher):
    Config = LevelConfig


class LevelThree(Level, preset=Preset(config={"level": 3})):
    """A preset of a field whose metadata must survive."""


def test_a_preset_sets_the_defaults_and_class_data_and_leaves_its_base_alone():
    assert BrightDouble.Config().gain == 2.0 and BrightDouble.Config().channels == (0, 1, 2)
    assert issubclass(BrightDouble.Config, BrightConfig) and BrightDouble.Config is not BrightConfig
    assert (BrightDouble.default_sigma, BrightDouble.paper) == (200.0, "a toy")
    assert BrightMatcher.Config().gain == 1.0 and BrightMatcher.default_sigma == 100.0
    frame = np.zeros((16, 16, 3), np.uint8)
    frame[3, 5] = 90
    view = np.full((8, 8, 4), 255, np.uint8)
    target = Target("x", "toy", (view,) * 3, ("a", "b", "c"))
    doubled, plain, config_given = BrightDouble(), BrightMatcher(), BrightDouble(BrightDouble.Config(gain=1.0))
    for m in (doubled, plain, config_given):
        m.prepare(target)
    assert doubled.match(frame).score == pytest.approx(2 * plain.match(frame).score) == pytest.approx(180.0)
    assert config_given.match(frame).score == pytest.approx(90.0)  # a default, not a constant


def test_a_preset_config_pickles_by_reference_and_keeps_field_metadata():
    cfg = LevelThree.Config()
    assert LevelThree.Config.__qualname__ == "LevelThree.Config" and LevelThree.Config.__name__ == "LevelThreeConfig"
    assert pickle.loads(pickle.dumps(LevelThree.Config)) is LevelThree.Config
    assert pickle.loads(pickle.dumps(cfg)) == cfg and cfg.level == 3
    level = {f.name: f for f in dataclasses.fields(LevelThree.Config)}["level"]
    assert level.metadata == {"hash": False, "help": "how loud"}
    assert "level" not in cfg.hashed_dict()


def test_a_preset_of_a_field_the_config_lacks_is_refused_naming_the_class():
    with pytest.raises(ConfigError, match=r"preset of test_presets\..*\.Loud: BrightConfig has no field volume"):
        class Loud(BrightMatcher, preset=Preset(config={"volume": 11})):
            pass


@pytest.mark.parametrize("name, preset", [*EFFNET_PRESETS.items(), *DINO_PRESETS.items()])
def test_every_preset_is_registered_under_its_name(name, preset):
    cls = get_matcher_class(name)
    assert cls.weights_spec is preset.weights_spec and cls.default_sigma == preset.default_sigma
    cfg = create_matcher(name).cfg
    assert {k: getattr(cfg, k) for k in preset.config} == dict(preset.config)


def test_the_lite_variants_are_effnets_matcher_with_other_data():
    for name in ("effnet-lite1", "effnet-lite2"):
        cls = get_matcher_class(name)
        assert issubclass(cls, EffnetMatcher) and issubclass(cls.Config, EffnetMatcher.Config)
        assert set(vars(cls)) <= {"__module__", "__qualname__", "__doc__", "__abstractmethods__", "_abc_impl",
                                  "Config", "weights_spec", "default_sigma", "name"}


@dataclass
class TableConfig(MatcherConfig):
    weights_by_role: dict = field(default_factory=dict, metadata={"help": "a weight per role"})
    roles: list = field(default_factory=list)


class Table(BrightMatcher):
    Config = TableConfig


def test_a_preset_may_set_a_dict_or_list_default_and_each_config_gets_its_own_copy():
    """Issue 43.2a: a dict or list value once failed as dataclasses' "mutable default"."""
    given = {"weights_by_role": {"a": 1.0, "b": [2.0]}, "roles": ["a", "b"]}

    class Weighted(Table, preset=Preset(config=given)):
        pass

    first, second = Weighted.Config(), Weighted.Config()
    assert first.weights_by_role == {"a": 1.0, "b": [2.0]} and first.roles == ["a", "b"]
    first.weights_by_role["b"].append(3.0)
    first.roles.append("c")
    assert second.weights_by_role == {"a": 1.0, "b": [2.0]} and second.roles == ["a", "b"]
    assert Weighted.Config().roles == ["a", "b"] and given["weights_by_role"] == {"a": 1.0, "b": [2.0]}
    field_ = {f.name: f for f in dataclasses.fields(Weighted.Config)}["weights_by_role"]
    assert field_.metadata == {"help": "a weight per role"}
    assert Weighted().id == Weighted().id and Weighted.Config(roles=["x"]).roles == ["x"]


def test_a_preset_sigma_that_contradicts_the_class_body_is_refused_naming_the_class():
    """Issue 43.2b: the preset's sigma once silently replaced the class body's own ``default_sigma``."""
    with pytest.raises(ConfigError, match=r"Contradicts: its body sets default_sigma=7\.0 and its preset 200\.0"):
        class Contradicts(BrightMatcher, preset=Preset(default_sigma=200.0)):
            default_sigma = 7.0

    class Agrees(BrightMatcher, preset=Preset(default_sigma=200.0)):
        default_sigma = 200.0

    class BodyOnly(BrightMatcher, preset=Preset(paper="a toy")):
        default_sigma = 7.0

    assert (Agrees.default_sigma, BodyOnly.default_sigma, BodyOnly.paper) == (200.0, 7.0, "a toy")
