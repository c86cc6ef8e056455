"""Procedural texture tiles for the rooms: named colours, patterns and materials (wood, fabric, tiles, wallpaper).

Everything here is drawn with numpy and OpenCV from an explicit random generator, so a
texture is a pure function of its arguments and the generator's state.
"""

from __future__ import annotations

import cv2
import numpy as np

TILE = 256

# Named colours, so a room's materials are drawn from a readable palette (pictures draw from all of them).
COLOURS: dict[str, tuple[int, int, int]] = {
    "red": (200, 30, 35), "dark red": (120, 20, 30), "orange": (235, 120, 25), "yellow": (240, 205, 40),
    "lime green": (150, 210, 50), "green": (40, 140, 60), "dark green": (25, 80, 40), "teal": (20, 140, 140),
    "light blue": (120, 180, 235), "blue": (30, 80, 200), "navy": (25, 35, 90), "purple": (110, 50, 160),
    "pink": (240, 130, 180), "magenta": (200, 40, 140), "white": (238, 238, 232), "cream": (240, 225, 190),
    "beige": (205, 185, 150), "tan": (190, 150, 100), "brown": (120, 75, 40), "dark brown": (70, 45, 28),
    "grey": (130, 130, 135), "dark grey": (60, 62, 66), "black": (22, 22, 25), "silver": (190, 192, 198),
    "gold": (212, 175, 55), "rose gold": (215, 150, 130), "olive": (110, 115, 45), "maroon": (110, 25, 45),
    "tortoiseshell": (110, 65, 30), "clear": (205, 215, 225), "mint": (160, 225, 190),
    "lavender": (185, 160, 220), "coral": (245, 120, 100), "khaki": (170, 160, 110),
}


def rgb(name: str) -> np.ndarray:
    """The named colour as floats."""
    return np.array(COLOURS[name], float)


def solid(colour: np.ndarray, rng: np.random.Generator, grain: float = 6.0, size: int = TILE) -> np.ndarray:
    """A flat colour with fine grain, because perfectly flat surfaces are what make renders look synthetic."""
    noise = rng.normal(0, grain, (size // 4, size // 4, 1))
    noise = cv2.resize(noise, (size, size), interpolation=cv2.INTER_LINEAR)[..., None]
    return np.clip(np.asarray(colour, float)[None, None] + noise, 0, 255).astype(np.uint8)


def pattern(kind: str, c1: np.ndarray, c2: np.ndarray, rng: np.random.Generator, size: int = TILE,
            scale: float = 1.0) -> np.ndarray:
    """A tile in ``c1`` with the named pattern in ``c2``."""
    img = solid(c1, rng, size=size)
    yy, xx = np.mgrid[:size, :size]
    period = max(8, int(size / (4 + 4 * scale)))
    if kind == "striped":
        sel = (yy // (period // 2)) % 2 == 0
    elif kind == "checked":
        sel = ((yy // period) + (xx // period)) % 2 == 0
    elif kind == "polka-dot":
        cy, cx = (yy % period) - period / 2, (xx % period) - period / 2
        sel = cy ** 2 + cx ** 2 < (period * 0.28) ** 2
    elif kind == "zigzag":
        sel = ((yy + np.abs((xx % period) - period / 2)) // (period // 2)) % 2 == 0
    elif kind == "plaid":
        sel = ((yy % period) < period // 4) | ((xx % period) < period // 4)
    elif kind == "camouflage":
        blob = cv2.resize(rng.normal(0, 1, (8, 8)), (size, size), interpolation=cv2.INTER_CUBIC)
        sel = blob > 0.3
    elif kind == "floral":
        sel = np.zeros((size, size), bool)
        for _ in range(int(10 * scale) + 6):
            cx, cy, r = rng.integers(0, size), rng.integers(0, size), int(rng.integers(6, 14))
            for k in range(5):
                a = 2 * np.pi * k / 5
                sel |= (xx - cx - r * np.cos(a)) ** 2 + (yy - cy - r * np.sin(a)) ** 2 < (r * 0.6) ** 2
    else:
        return img
    img[sel] = solid(c2, rng, size=size)[sel]
    return img


def shade(colour: np.ndarray, factor: float) -> np.ndarray:
    return np.clip(np.asarray(colour, float) * factor, 0, 255)


# ------------------------------------------------------------------ room materials
def wood(rng: np.random.Generator, base: np.ndarray, size: int = TILE, planks: int = 4) -> np.ndarray:
    """Planks with grain: floors, tables, cabinets."""
    img = np.zeros((size, size, 3), float)
    ph = size // planks
    for k in range(planks):
        tone = np.asarray(base, float) * rng.uniform(0.85, 1.12)
        grain = cv2.resize(rng.normal(0, 1, (2, 64)), (size, ph), interpolation=cv2.INTER_CUBIC)
        img[k * ph:(k + 1) * ph] = tone[None, None] * (1 + 0.08 * grain[..., None])
        img[k * ph:k * ph + 2] *= 0.6
    return np.clip(img, 0, 255).astype(np.uint8)


def fabric(rng: np.random.Generator, base: np.ndarray, size: int = TILE) -> np.ndarray:
    """Carpet, upholstery, bedding: colour noise at two scales."""
    coarse = cv2.resize(rng.normal(0, 1, (8, 8)), (size, size), interpolation=cv2.INTER_CUBIC)
    fine = rng.normal(0, 1, (size, size))
    img = np.asarray(base, float)[None, None] * (1 + 0.06 * coarse[..., None] + 0.05 * fine[..., None])
    return np.clip(img, 0, 255).astype(np.uint8)


def tiles(rng: np.random.Generator, base: np.ndarray, size: int = TILE, n: int = 4) -> np.ndarray:
    img = fabric(rng, base, size).astype(float) * 1.0
    step = size // n
    img[::step] *= 0.55
    img[:, ::step] *= 0.55
    return np.clip(img, 0, 255).astype(np.uint8)


def wallpaper(rng: np.random.Generator, base: np.ndarray, size: int = TILE) -> np.ndarray:
    kind = rng.choice(["plain", "plain", "striped", "plain"])
    other = shade(base, rng.uniform(0.85, 0.95))
    img = pattern(str(kind), base, other, rng, size, scale=0.5)
    return img
