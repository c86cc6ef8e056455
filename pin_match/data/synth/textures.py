"""Procedural texture tiles: colours, patterns, photo prints and text, room materials.

Everything here is drawn with numpy and OpenCV from an explicit random generator, so a
texture is a pure function of its arguments and the generator's state.
"""

from __future__ import annotations

import cv2
import numpy as np

TILE = 256

# Named colours, so that what is painted is exactly what the descriptions say.
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

PATTERNS = ("plain", "striped", "checked", "polka-dot", "zigzag", "camouflage", "plaid", "floral")
WORDS = ("NOVA", "ZEN", "HELLO", "LOVE", "PARIS", "RIO", "SURF", "CAT", "GO!", "ACE", "MOM", "BOSS", "JOY", "KAI",
         "MAX", "OK", "SUN", "YES", "LUNA", "PIXEL", "ROCK", "COOL", "BEST", "DAD")


def rgb(name: str, rng: np.random.Generator | None = None, jitter: float = 0.0) -> np.ndarray:
    """The named colour, optionally jittered a little so two 'blue' objects are not pixel-identical."""
    base = np.array(COLOURS[name], float)
    if rng is not None and jitter:
        base = base * (1 + rng.uniform(-jitter, jitter)) + rng.uniform(-jitter, jitter, 3) * 60
    return np.clip(base, 0, 255)


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


def photo(img: np.ndarray, rgba: np.ndarray, centre=(0.5, 0.5), scale: float = 0.45) -> np.ndarray:
    """Print an RGBA photo onto a tile, its longer side ``scale`` of the tile's (in place, also returned)."""
    size = img.shape[0]
    h, w = rgba.shape[:2]
    k = scale * size / max(h, w)
    pw, ph = max(1, int(round(w * k))), max(1, int(round(h * k)))
    small = cv2.resize(rgba, (pw, ph), interpolation=cv2.INTER_AREA if k < 1 else cv2.INTER_CUBIC)
    x0 = int(np.clip(round(centre[0] * size - pw / 2), 0, size - pw))
    y0 = int(np.clip(round(centre[1] * size - ph / 2), 0, size - ph))
    alpha = small[..., 3:].astype(np.float32) / 255.0
    region = img[y0:y0 + ph, x0:x0 + pw].astype(np.float32)
    img[y0:y0 + ph, x0:x0 + pw] = np.round(region * (1 - alpha) + small[..., :3] * alpha).astype(np.uint8)
    return img


def text(img: np.ndarray, word: str, colour: np.ndarray, centre=(0.5, 0.5), width: float = 0.8,
         label: np.ndarray | None = None) -> np.ndarray:
    """Print a word, fitted to ``width`` of the tile, centred at ``centre`` (in place, also returned).

    ``label`` paints a patch of that colour behind the word, so it stays legible on a pattern.
    """
    size = img.shape[0]
    font = cv2.FONT_HERSHEY_DUPLEX
    (tw, th), _ = cv2.getTextSize(word, font, 1.0, 2)
    scale = width * size / max(tw, 1)
    thick = max(1, int(round(scale * 2)))
    (tw, th), _ = cv2.getTextSize(word, font, scale, thick)
    org = (int(centre[0] * size - tw / 2), int(centre[1] * size + th / 2))
    if label is not None:
        pad = max(3, th // 3)
        cv2.rectangle(img, (org[0] - pad, org[1] - th - pad), (org[0] + tw + pad, org[1] + pad),
                      tuple(int(v) for v in label), -1)
    cv2.putText(img, word, org, font, scale, tuple(int(v) for v in colour), thick, cv2.LINE_AA)
    return img


def shade(colour: np.ndarray, factor: float) -> np.ndarray:
    return np.clip(np.asarray(colour, float) * factor, 0, 255)


def contrasting(colour: np.ndarray) -> np.ndarray:
    """White on dark colours, near-black on light ones: for printed text."""
    return np.array([245.0, 245, 240]) if np.dot(colour, [0.3, 0.59, 0.11]) < 140 else np.array([25.0, 25, 30])


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
