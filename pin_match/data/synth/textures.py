"""Procedural texture tiles: colours, patterns, printed decals and text, room materials.

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
DECALS = ("star", "heart", "circle", "triangle", "lightning bolt", "crescent moon", "flower", "diamond", "cross",
          "paw print", "anchor", "smiley face")
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


def _star(n: int, r_out: float, r_in: float) -> np.ndarray:
    a = np.pi / 2 + np.arange(2 * n) * np.pi / n
    r = np.where(np.arange(2 * n) % 2 == 0, r_out, r_in)
    return np.stack([r * np.cos(a), -r * np.sin(a)], 1)


def decal(img: np.ndarray, kind: str, colour: np.ndarray, centre=(0.5, 0.5),  # noqa: C901 - a flat switch
          scale: float = 0.35) -> np.ndarray:
    """Print a logo-like shape onto a tile (in place, also returned)."""
    size = img.shape[0]
    c = np.array(centre) * size
    s = scale * size / 2
    col = tuple(int(v) for v in colour)

    def poly(points: np.ndarray) -> None:
        cv2.fillPoly(img, [np.round(c + points * s).astype(np.int32)], col, cv2.LINE_AA)

    def disc(dx: float, dy: float, r: float) -> None:
        cv2.circle(img, (int(c[0] + dx * s), int(c[1] + dy * s)), max(1, int(r * s)), col, -1, cv2.LINE_AA)

    if kind == "star":
        poly(_star(5, 1.0, 0.42))
    elif kind == "heart":
        t = np.linspace(0, 2 * np.pi, 60)
        poly(np.stack([16 * np.sin(t) ** 3, -(13 * np.cos(t) - 5 * np.cos(2 * t) - 2 * np.cos(3 * t) - np.cos(4 * t))],
                      1) / 17)
    elif kind == "circle":
        disc(0, 0, 0.9)
    elif kind == "triangle":
        poly(np.array([[0, -0.95], [0.95, 0.75], [-0.95, 0.75]]))
    elif kind == "lightning bolt":
        poly(np.array([[0.2, -1], [-0.5, 0.1], [0.0, 0.1], [-0.25, 1], [0.55, -0.2], [0.05, -0.2], [0.35, -1]]))
    elif kind == "crescent moon":
        disc(0, 0, 0.9)
        bg = tuple(int(v) for v in img[int(np.clip(c[1] - s * 0.95, 0, size - 1)), int(np.clip(c[0] - s * 0.95, 0,
                                                                                                   size - 1))])
        cv2.circle(img, (int(c[0] + 0.4 * s), int(c[1] - 0.2 * s)), int(0.75 * s), bg, -1, cv2.LINE_AA)
    elif kind == "flower":
        for k in range(6):
            a = 2 * np.pi * k / 6
            disc(0.55 * np.cos(a), 0.55 * np.sin(a), 0.38)
        disc(0, 0, 0.3)
    elif kind == "diamond":
        poly(np.array([[0, -1], [0.65, 0], [0, 1], [-0.65, 0]]))
    elif kind == "cross":
        poly(np.array([[-0.3, -0.95], [0.3, -0.95], [0.3, -0.3], [0.95, -0.3], [0.95, 0.3], [0.3, 0.3], [0.3, 0.95],
                       [-0.3, 0.95], [-0.3, 0.3], [-0.95, 0.3], [-0.95, -0.3], [-0.3, -0.3]]))
    elif kind == "paw print":
        disc(0, 0.35, 0.5)
        for dx, dy in ((-0.62, -0.3), (-0.22, -0.68), (0.22, -0.68), (0.62, -0.3)):
            disc(dx, dy, 0.2)
    elif kind == "anchor":
        cv2.line(img, tuple(np.int32(c + [0, -0.8 * s])), tuple(np.int32(c + [0, 0.8 * s])), col, max(2, int(s * .18)))
        cv2.line(img, tuple(np.int32(c + [-0.45 * s, -0.4 * s])), tuple(np.int32(c + [0.45 * s, -0.4 * s])), col,
                 max(2, int(s * .15)))
        cv2.ellipse(img, tuple(np.int32(c + [0, 0.2 * s])), (int(0.75 * s), int(0.6 * s)), 0, 0, 180, col,
                    max(2, int(s * .15)))
    elif kind == "smiley face":
        disc(0, 0, 0.95)
        dark = tuple(int(v * 0.25) for v in colour)
        for dx in (-0.35, 0.35):
            cv2.circle(img, (int(c[0] + dx * s), int(c[1] - 0.25 * s)), max(1, int(0.12 * s)), dark, -1)
        cv2.ellipse(img, tuple(np.int32(c + [0, 0.1 * s])), (int(0.5 * s), int(0.45 * s)), 0, 20, 160, dark,
                    max(2, int(s * .1)))
    else:
        raise ValueError(f"unknown decal kind {kind!r}")
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
