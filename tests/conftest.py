"""Shared fixtures: a tiny hand-made frame-set whose every pixel of ground truth is known."""

from __future__ import annotations

import os

import numpy as np
import pytest

from pin_match.contract.matcher import Target

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")


def make_view(color: tuple[int, int, int], size: int = 96, stripe: tuple[int, int, int] | None = None) -> np.ndarray:
    """An RGBA reference: a coloured disc (optionally striped) on a transparent background."""
    yy, xx = np.mgrid[:size, :size]
    inside = (yy - size / 2) ** 2 + (xx - size / 2) ** 2 < (size * 0.4) ** 2
    view = np.zeros((size, size, 4), np.uint8)
    view[inside, :3] = color
    if stripe is not None:
        view[inside & ((xx // 8) % 2 == 0), :3] = stripe
    view[inside, 3] = 255
    return view


RED, GREEN, BLUE, YELLOW = (200, 30, 30), (30, 200, 30), (30, 30, 200), (255, 255, 0)
MUG_DESCRIPTIONS = ("a red mug", "a striped cup", "a mug with yellow stripes")


def striped_mug(descriptions: tuple[str, str, str] = MUG_DESCRIPTIONS) -> Target:
    """'mug_x' (a mug) seen as three discs with yellow stripes, one red, one green, one blue."""
    return Target("mug_x", "mug", tuple(make_view(c, stripe=YELLOW) for c in (RED, GREEN, BLUE)), descriptions)


def red_mug(descriptions: tuple[str, str, str]) -> Target:
    """'mug_x' (a mug): a red disc with yellow stripes, the same red disc without, and a blue disc."""
    return Target("mug_x", "mug", (make_view(RED, stripe=YELLOW), make_view(RED), make_view(BLUE)), descriptions)


def noise_frame(height: int, width: int, seed: int = 0) -> np.ndarray:
    """A frame of uniform random pixels."""
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def paint(image: np.ndarray, mask: np.ndarray, value: int, view: np.ndarray, x0: int, y0: int) -> None:
    """Paste an RGBA view into a frame and its mask value into the instance mask."""
    h, w = view.shape[:2]
    alpha = view[..., 3] > 0
    region = image[y0:y0 + h, x0:x0 + w]
    region[alpha] = view[..., :3][alpha]
    mask[y0:y0 + h, x0:x0 + w][alpha] = value


@pytest.fixture
def own_registry(monkeypatch):
    """The matcher registry, built-ins imported, as a copy the test may change: its names are gone after it.

    A built-in registers when its module is first imported, once per process: imported into a copy, it
    would be missing from the real registry for every later test.
    """
    from pin_match.contract import registry

    registry.available_names()
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


@pytest.fixture(scope="session")
def tiny_frameset(tmp_path_factory):
    """2 episodes (train, val) x 4 frames, 640x360, with depth.

    Per episode, frame 0 shows the target, frame 1 a same-category distractor, frame 2 an
    other-category distractor, frame 3 nothing.
    """
    from pin_match.data.writer import FrameSetWriter

    root = tmp_path_factory.mktemp("fs") / "tiny"
    w = FrameSetWriter(root, "tiny")
    objects = {
        "mug_a": ("mug", "train", (200, 30, 30), (255, 255, 0)),
        "mug_b": ("mug", "train", (30, 30, 200), None),
        "ball_a": ("ball", "train", (30, 200, 30), (0, 0, 0)),
        "mug_c": ("mug", "val", (220, 120, 20), (20, 20, 20)),
        "mug_d": ("mug", "val", (120, 20, 220), None),
        "ball_b": ("ball", "val", (20, 180, 180), None),
    }
    views = {}
    for oid, (cat, split, color, stripe) in objects.items():
        views[oid] = make_view(color, stripe=stripe)
        w.add_object(oid, cat, split, [views[oid]] * 3, [f"a {cat} number {oid} view {k}" for k in range(3)])
    for ep, split, (t, s, o) in (("ep_train", "train", ("mug_a", "mug_b", "ball_a")),
                                 ("ep_val", "val", ("mug_c", "mug_d", "ball_b"))):
        w.add_episode(ep, split, "scene0", t, [s, o])
        roles = w.roles(ep)
        for step, oid in enumerate([t, s, o, None]):
            image = np.full((640, 360, 3), 90, np.uint8)
            mask = np.zeros((640, 360), np.uint16)
            depth = np.full((640, 360), 3.0, np.float32)
            legend = {}
            if oid is not None:
                paint(image, mask, 1, views[oid], 100, 300)
                depth[mask == 1] = 1.5
                legend[1] = (oid, roles[oid])
            w.add_frame(ep, step, image, mask, legend, depth)
    return w.close()


@pytest.fixture(scope="session")
def real_frameset(tmp_path_factory):
    """The real-photo frame-set (the recolour source, seed 0): built once per session from scikit-image's photos."""
    pytest.importorskip("skimage")
    from pin_match.data.sources.recolour import build

    return build(tmp_path_factory.mktemp("real") / "realset")


@pytest.fixture(scope="session")
def shipped_pasted(tmp_path_factory):
    """The look-alike set shipped with pin_match, pasted variant: built once per session (offline)."""
    from pin_match.data.sources.lookalike_set import build

    return build(tmp_path_factory.mktemp("lookalikes") / "pasted", variant="pasted")


@pytest.fixture(scope="session")
def default_synth(tmp_path_factory):
    """The default set of ``pin-match synth`` (``SynthSize()``: scanned look-alike families, 30 episodes): rendered
    once per session."""
    from pin_match.data.synth import SynthSize, generate

    return generate(tmp_path_factory.mktemp("synth_default") / "frameset", SynthSize(), workers=2)


@pytest.fixture(scope="module")
def dino_cfg(tmp_path_factory):
    """The tiny timm ViT at 64 px: a 4 x 4 patch grid of 64-dim tokens (feature store and training tests)."""
    from tiny_weights import save_tiny_timm_vit

    return dict(model_name="test_vit", img_size=64, weights=str(save_tiny_timm_vit(tmp_path_factory.mktemp("vit"))))


@pytest.fixture(scope="module")
def store(tiny_frameset, dino_cfg, tmp_path_factory):
    """A feature store of the tiny frame-set under the tiny ViT."""
    from pin_match.scoring.options import RunOptions
    from pin_match.training.features import build_features

    return build_features(tiny_frameset, "dino", overrides=dino_cfg, out=tmp_path_factory.mktemp("features"),
                          run=RunOptions(progress=False))
