"""Every registered matcher honours the interface: tiny weights, odd sizes, determinism, valid results.

A built-in added to the registry without a tiny-weights entry here fails
``test_every_builtin_is_covered``, so no matcher escapes the contract.
"""

from __future__ import annotations

import numpy as np
import pytest
from tiny_weights import tiny_overrides

from conftest import make_view
from pin_match import Target, create_matcher
from pin_match.registry import BUILTINS

FRAMES = {
    "pin 640x360": (640, 360, 3),
    "odd 333x517": (333, 517, 3),
    "square 200x200": (200, 200, 3),
    "grayscale 300x220": (300, 220),
}


@pytest.fixture(scope="module")
def overrides(tmp_path_factory):
    return tiny_overrides(tmp_path_factory.mktemp("tiny_weights"))


@pytest.fixture(scope="module")
def target():
    views = (make_view((200, 30, 30), stripe=(255, 255, 0)), make_view((30, 160, 30)), make_view((30, 30, 200)))
    return Target("mug_x", "mug", views, ("a red mug with yellow stripes", "a red cup", "a mug on the floor"))


def frames() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    out = {}
    for name, shape in FRAMES.items():
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        view = make_view((200, 30, 30), stripe=(255, 255, 0))[..., :3] if len(shape) == 3 else None
        if view is not None:  # paste the target so matchers have something to find
            image[40:136, 40:136] = np.where(view.any(-1, keepdims=True), view, image[40:136, 40:136])
        out[name] = image
    return out


def test_every_builtin_is_covered(overrides):
    assert set(BUILTINS) == set(overrides)


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_contract(name, overrides, target, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    m = create_matcher(name, **overrides[name])
    assert m.modality.value in ("visual", "textual", "category") and np.isfinite(m.default_sigma)
    m.prepare(target)
    images = frames()
    batch = m.match_batch(list(images.values()))
    for (label, image), r in zip(images.items(), batch):
        h, w = image.shape[:2]
        assert np.isfinite(r.score), label
        assert r.points.ndim == 2 and r.points.shape[1] == 2, label
        if len(r.points):
            assert (r.points >= 0).all() and (r.points[:, 0] < w).all() and (r.points[:, 1] < h).all(), label
        assert len(r.scores_of_points()) == len(r.points)
        assert r.points_at(r.score + 1.0).shape == (0, 2)  # above the frame score nothing is matched
        again = m.match(image)  # deterministic, and a batch of one equals the batch
        assert again.score == pytest.approx(r.score, rel=1e-4, abs=1e-4), label
        assert again.points.shape == r.points.shape, label
        np.testing.assert_allclose(again.points, r.points, atol=1e-3)
