"""Every registered matcher honours the contract, checked by the same function plug-in authors call.

``pin_match.contract.testing.check_matcher`` runs on every name the registry knows (built-ins and
installed entry points) with the tiny local weights of ``tests/tiny_weights.py``; a matcher
that needs weights and has no entry there fails here, so no matcher escapes the contract.
"""

from __future__ import annotations

import numpy as np
import pytest
from tiny_weights import tiny_overrides

from pin_match import CropConfig, CropMatcher, MatchResult, Modality, Target, register_matcher
from pin_match.contract.registry import available_names
from pin_match.contract.testing import ContractError, check_matcher, contract_frames, contract_target


@pytest.fixture(scope="module")
def overrides(tmp_path_factory):
    return tiny_overrides(tmp_path_factory.mktemp("tiny_weights"))


@pytest.mark.parametrize("name", available_names())
def test_contract(name, overrides, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    scores = check_matcher(name, **overrides.get(name, {}))
    assert set(scores) == set(contract_frames(contract_target()))
    assert all(np.isfinite(list(scores.values())))


class _Flaky(CropMatcher):
    """Breaks three rules on purpose: it reads the category, and its score drifts between calls."""

    modality = Modality.VISUAL
    calls = 0

    def _prepare(self, target: Target) -> None:
        pass

    def prepare(self, target: Target) -> None:  # bypasses the base class, which would hide the label
        self._prepare(target)
        self._target = target

    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        type(self).calls += 1
        return [MatchResult(score=float(type(self).calls)) for _ in crops]


def test_check_matcher_names_every_broken_rule():
    with pytest.raises(ContractError) as err:
        check_matcher(_Flaky)
    text = str(err.value)
    assert text.startswith("matcher _Flaky breaks the contract")
    assert "shown the category label" in text
    assert "PIN 640x360: a batch gives score" in text and "not deterministic" in text


def test_check_matcher_accepts_a_plain_plugin():
    @register_matcher("test-contract-mean")
    class Mean(CropMatcher):
        Config = CropConfig

        def _prepare(self, target: Target) -> None:
            self._mean = float(target.views[0][..., :3].mean())

        def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
            return [MatchResult(score=-abs(float(c.mean()) - self._mean), points=[[1.0, 2.0]]) for c in crops]

    scores = check_matcher("test-contract-mean")
    assert len(scores) == 4 and all(s <= 0 for s in scores.values())
