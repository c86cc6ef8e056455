"""A plug-in whose Config misses what its contract base needs is named with its fix, not left to fail in matching."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from pin_match.contract import (
    ConfigError,
    ContractError,
    CropConfig,
    CropMatcher,
    MatcherConfig,
    MatchResult,
    Target,
    check_matcher,
    register_matcher,
)
from pin_match.contract.testing import FRAME_SHAPES


@dataclass
class OldStyleConfig(MatcherConfig):  # a CropMatcher needs CropConfig's `crops`
    bins: int = 8


def old_style_class(config: type) -> type:
    class GrayHist(CropMatcher):
        Config = config

        def _prepare(self, target: Target) -> None:
            self.ref = 1.0

        def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
            return [MatchResult(score=1.0) for _ in crops]

    return GrayHist


def test_registration_refuses_a_config_without_what_the_base_class_needs():
    with pytest.raises(ConfigError) as err:
        register_matcher("old-gray-hist")(old_style_class(OldStyleConfig))
    message = str(err.value)
    assert "OldStyleConfig must derive from CropConfig" in message
    assert "write `class OldStyleConfig(CropConfig)`" in message and "\n" not in message


def test_check_matcher_names_the_same_fix_in_one_line():
    with pytest.raises(ContractError) as err:
        check_matcher(old_style_class(OldStyleConfig))
    assert "must derive from CropConfig" in str(err.value) and "\n" not in str(err.value)


def test_a_matcher_written_to_this_contract_passes():
    @dataclass
    class NewConfig(CropConfig):
        bins: int = 8

    scores = check_matcher(old_style_class(NewConfig))
    assert set(scores) == set(FRAME_SHAPES) and all(s == 1.0 for s in scores.values())
