"""Procedural shapes of the 18 categories: an ``ObjectSpec`` in, one mesh and its texture atlas out.

Conventions: metres, z up, the object's front faces -y (where logos go), it rests on z = 0.
Proportions are jittered by ``look.scale`` and by per-instance noise scaled with the
category's ``spread``, so near-uniform categories stay near-uniform.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from pin_match.data.synth import prints
from pin_match.data.synth import textures as tx
from pin_match.data.synth.objects import CATEGORY_SPECS, ObjectSpec
from pin_match.data.synth.parts import FRONT, UP, Parts, flat_ring
from pin_match.data.synth.shapes import (
    Mesh,
    box,
    cylinder,
    ellipsoid,
    lathe,
    merge,
    rot_x,
    rot_y,
    rot_z,
    split_facing,
    torus,
)


# ------------------------------------------------------------------ categories
def backpack(p: Parts) -> None:
    w, d, h = {"hiking backpack": (0.32, 0.2, 0.52), "small backpack": (0.22, 0.11, 0.28)}.get(
        p.look.variant, (0.3, 0.15, 0.42))
    w, d, h = p.j(w), p.j(d), p.j(h)
    front, plain, trim = p.body(0.5, 0.3), p.body(logo=False), p.solid(p.c2)
    p.boxed(box(w, d, h).moved((0, 0, h / 2)), front, plain)
    p.add(box(w * 0.8, d * 0.35, h * 0.38).moved((0, -d / 2 - d * 0.15, h * 0.25)), trim)
    p.add(box(w, d * 0.9, h * 0.12).moved((0, 0, h + h * 0.04)), plain)
    for sx in (-1, 1):
        p.add(box(0.045, 0.02, h * 0.85).moved((sx * w * 0.28, d / 2 + 0.012, h * 0.5)), trim)
    p.add(torus(0.04, 0.008, np.pi, 12, 6).moved((0, 0, h + h * 0.1)), trim)
    if p.look.variant == "hiking backpack":
        p.add(cylinder(0.07, w * 1.1, 16).moved((0, 0, -w * 0.55), rot_y(np.pi / 2)), trim)


def bag(p: Parts) -> None:
    v = p.look.variant
    front, plain, trim = p.body(0.5, 0.5), p.body(logo=False), p.solid(p.c2)
    if v == "duffel bag":
        L, r = p.j(0.5), p.j(0.14)
        body = cylinder(r, L, 24).moved((0, 0, -L / 2), rot_y(np.pi / 2)).moved((0, 0, r))
        p.add(rotate_uv(body), front)
        for sx in (-1, 1):
            p.add(torus(0.08, 0.012, np.pi, 12, 6).moved((sx * L * 0.2, 0, 2 * r - 0.01), rot_z(np.pi / 2)), trim)
        return
    w, d, h = {"tote bag": (0.38, 0.14, 0.36), "handbag": (0.28, 0.12, 0.2), "messenger bag": (0.36, 0.1, 0.28)}[v]
    w, d, h = p.j(w), p.j(d), p.j(h)
    m = box(w, d, h)
    if v in ("tote bag", "handbag"):  # trapezoid: narrower at the top
        m.vertices = m.vertices * np.where(m.vertices[:, 2:3] > 0, [0.85, 0.8, 1], [1, 1, 1])
    p.boxed(m.moved((0, 0, h / 2)), front, plain)
    if v == "messenger bag":
        p.add(box(w * 1.01, 0.01, h * 0.55).moved((0, -d / 2 - 0.006, h * 0.72)), trim)
        p.add(torus(0.18, 0.01, np.pi, 16, 6).moved((0, 0, h)), trim)
    else:
        r = 0.1 if v == "tote bag" else 0.08
        for sy in ((-1, 1) if v == "tote bag" else (0,)):
            p.add(torus(r, 0.01, np.pi, 16, 6).moved((0, sy * d * 0.3, h * 0.98)), trim)


def rotate_uv(mesh: Mesh) -> Mesh:
    """Swap U and V so a logo printed upright in the tile stays upright on a lying cylinder."""
    return Mesh(mesh.vertices, mesh.uvs[:, ::-1].copy(), mesh.faces)


def ball(p: Parts) -> None:
    r = p.j({"beach ball": 0.16, "soccer ball": 0.11, "rubber ball": 0.08, "tennis ball": 0.035}[p.look.variant])
    lk = p.look
    img = tx.pattern(lk.pattern if lk.pattern != "plain" else "plain", p.c1, p.c2, p.rng, scale=0.6)
    if lk.variant == "tennis ball":
        cv2.ellipse(img, (128, 128), (90, 40), 0, 0, 360, (240, 240, 240), 6, cv2.LINE_AA)
    if lk.photo:
        tx.photo(img, prints.image(lk.photo), (0.75, 0.45), 0.3)
    if lk.word:
        tx.text(img, lk.word, tx.contrasting(p.c1), (0.25, 0.5), 0.22)
    p.add(ellipsoid(r, r, r, 28), p.tile(img))


def book(p: Parts) -> None:
    w, d, t = {"hardcover book": (0.17, 0.24, 0.035), "paperback book": (0.13, 0.2, 0.025),
               "notebook": (0.15, 0.21, 0.015)}[p.look.variant]
    w, d, t = p.j(w), p.j(d), p.j(t)
    img = tx.pattern(p.look.pattern, p.c1, tx.shade(p.c1, 0.7), p.rng)
    if p.look.photo:
        tx.photo(img, prints.image(p.look.photo), (0.5, 0.6), 0.55)
    title = p.look.word or "".join(p.rng.choice(list("ABCDEFGHIJKLMNOPRSTUVW"), 5))
    tx.text(img, title, tx.contrasting(p.c1), (0.5, 0.22), 0.7)
    cover, plain = p.tile(img), p.solid(p.c1)
    pages = tx.solid(p.c2, p.rng)
    pages[::6] = (pages[::6] * 0.85).astype(np.uint8)
    c = 0.004
    p.boxed(box(w, d, c).moved((0, 0, t - c / 2)), cover, plain, facing=UP)
    p.add(box(w, d, c).moved((0, 0, c / 2)), plain)
    p.add(box(w - 0.006, d - 0.008, t - 2 * c).moved((0.003, 0, t / 2)), p.tile(pages))
    p.add(box(0.006, d, t).moved((-w / 2 + 0.003, 0, t / 2)), plain)


def camera(p: Parts) -> None:
    v = p.look.variant
    w, d, h, lens = {"DSLR camera": (0.14, 0.08, 0.1, 0.035), "compact camera": (0.11, 0.035, 0.065, 0.02),
                     "instant camera": (0.12, 0.09, 0.11, 0.04)}[v]
    w, d, h = p.j(w), p.j(d), p.j(h)
    front, plain, trim = p.body(0.5, 0.25), p.body(logo=False), p.solid(p.c2)
    p.boxed(box(w, d, h).moved((0, 0, h / 2)), front, plain)
    glass = tx.solid(tx.rgb("black"), p.rng)
    cv2.circle(glass, (100, 100), 40, (90, 110, 140), -1, cv2.LINE_AA)
    cv2.circle(glass, (128, 128), 110, (50, 50, 60), 10)
    depth = lens * (1.8 if v == "DSLR camera" else 0.8)
    lens_mesh = cylinder(lens, depth, 24).moved((0, 0, 0), rot_x(np.pi / 2))
    side, cap = split_facing(lens_mesh, FRONT)
    p.add(cap.moved((0, -d / 2, h * 0.45)), p.tile(glass))
    p.add(side.moved((0, -d / 2, h * 0.45)), trim)
    p.add(box(w * 0.25, d * 0.6, h * 0.2).moved((-w * 0.2 if v != "instant camera" else w * 0.25, 0, h * 1.08)),
          plain)
    p.add(cylinder(0.008, 0.008, 12).moved((w * 0.35, 0, h)), trim)


def cellphone(p: Parts) -> None:
    w, d, t = p.j(0.075, 0.3), p.j(0.155, 0.3), 0.009
    back = p.body(0.5, 0.55)
    p.boxed(box(w, d, t).moved((0, 0, t / 2)), back, p.solid(p.c1), facing=UP)
    p.add(box(0.03, 0.03, 0.003).moved((-w * 0.22, -d * 0.36, t + 0.0015)), p.solid(p.c2))


def eyeglasses(p: Parts) -> None:
    rect = p.look.variant == "rectangular glasses"
    r, thick = p.j(0.024, 0.4), 0.0035 if p.rng.random() < 0.5 else 0.005
    frame = p.body(logo=False)
    lens = p.solid(tx.shade(p.c2, 0.9), grain=2)
    sx, sz = (1.25, 0.8) if rect else (1.0, 1.0)
    gap = 0.012
    for side in (-1, 1):
        cx = side * (gap / 2 + r * sx)
        p.add(torus(r, thick, 2 * np.pi, 24, 6).scaled((sx, 1, sz)).moved((cx, 0, r)), frame)
        p.add(ellipsoid(r * 0.95, 0.002, r * 0.95, 16).scaled((sx, 1, sz)).moved((cx, 0, r)), lens)
        p.add(box(0.005, 0.13, 0.005).moved((side * (gap / 2 + 2 * r * sx), 0.065, r * (1 + 0.4 * sz))), frame)
    p.add(torus(gap / 2, thick * 0.8, np.pi, 8, 5).moved((0, 0, r * (1 + 0.3 * sz))), frame)


def hat(p: Parts) -> None:
    v = p.look.variant
    crown_tile, band = p.body(0.75, 0.68), p.solid(p.c2)  # v 0.68: the crown side, below the top cap
    plain = p.body(logo=False)
    r = p.j(0.095)
    if v == "baseball cap":
        phi = np.linspace(0, np.pi / 2, 8)
        p.add(lathe(r * np.cos(phi), r * 0.9 * np.sin(phi), 24, caps=False), crown_tile)
        brim = ellipsoid(r * 0.85, r * 0.75, 0.006, 20).moved((0, -r * 0.95, 0.006))
        p.add(brim, plain)
        p.add(cylinder(0.01, 0.008, 8).moved((0, 0, r * 0.9)), band)
    elif v == "bucket hat":
        p.add(lathe([r, r * 0.85, r * 0.8, 0], [0.03, 0.1, 0.12, 0.125], 24), crown_tile)
        p.add(lathe([r * 1.6, r, r, r * 1.6], [0, 0.035, 0.04, 0.005], 24, caps=False), plain)
        p.add(cylinder(r * 1.005, 0.015, 24).moved((0, 0, 0.04)), band)
    elif v == "beanie":
        phi = np.linspace(0, np.pi / 2, 8)
        p.add(lathe(r * np.cos(phi), 0.04 + r * 1.1 * np.sin(phi), 24, caps=False), crown_tile)
        p.add(lathe([r * 1.03, r * 1.03], [0, 0.05], 24, caps=False), band)
        p.add(ellipsoid(0.025, 0.025, 0.022, 10).moved((0, 0, 0.04 + r * 1.1 + 0.01)), band)
    else:
        p.add(lathe([r * 0.95, r * 0.9, r * 0.7, 0], [0.01, 0.1, 0.12, 0.115], 24).scaled((1, 1.15, 1)), crown_tile)
        p.add(flat_ring(r * 0.9, r * 1.6, 0.006).scaled((1, 1.15, 1)), plain)
        p.add(cylinder(r * 0.955, 0.025, 24).scaled((1, 1.15, 1)).moved((0, 0, 0.008)), band)


def headphones(p: Parts) -> None:
    v = p.look.variant
    r = p.j(0.085, 0.5)
    cup = 0.045 if v != "on-ear headphones" else 0.035
    shell, cushion = p.body(0.5, 0.5), p.solid(p.c2)
    p.add(torus(r, 0.012, np.pi, 20, 8).scaled((1, 1.8, 1)).moved((0, 0, cup + 0.01)), p.body(logo=False))
    for side in (-1, 1):
        m = cylinder(cup, 0.03, 20).moved((0, 0, 0), rot_y(side * np.pi / 2)).moved((side * (r + 0.012), 0, cup))
        p.add(m, shell)
        p.add(ellipsoid(0.012, cup * 0.95, cup * 0.95, 14).moved((side * (r - 0.008), 0, cup)), cushion)
    if v == "gaming headset":
        p.add(cylinder(0.004, 0.11, 8).moved((0, 0, 0), rot_x(np.pi / 2 + 0.3)).moved((-r - 0.03, 0, cup * 0.7)),
              cushion)


def keys(p: Parts) -> None:
    metal = p.solid(p.c1, grain=12)
    ring_r = p.j(0.015, 0.3)
    p.add(torus(ring_r, 0.0015, 2 * np.pi, 16, 5).moved((0, 0, 0.0015), rot_x(np.pi / 2)), metal)
    n = 2 + (p.look.variant == "set of keys")
    for k in range(n + 1):
        a = -0.6 + 1.2 * k / n + p.rng.normal(0, 0.05)
        length = p.j(0.055, 0.3)
        head = cylinder(0.012, 0.0025, 14).moved((0, ring_r + 0.012, 0))
        blade = box(0.008, length, 0.0022).moved((0, ring_r + 0.024 + length / 2, 0.0011))
        p.add(merge([head, blade]).moved((0, 0, 0.0005 * k), rot_z(a)), metal)
    tag = tx.solid(p.c2, p.rng)
    if p.look.word:
        tx.text(tag, p.look.word, tx.contrasting(p.c2), (0.5, 0.5), 0.8)
    p.boxed(box(0.025, 0.04, 0.004).moved((0, -ring_r - 0.022, 0.002)), p.tile(tag), p.solid(p.c2), facing=UP)


def laptop(p: Parts) -> None:
    w, d = p.j(0.33, 0.4), p.j(0.23, 0.4)
    t = 0.012
    shell = p.solid(p.c1, grain=4)
    kb = tx.solid(tx.shade(p.c1, 0.9), p.rng, grain=3)
    key_colour = tuple(int(c) for c in p.c2)
    for row in range(5):
        for col in range(12):
            x0, y0 = 14 + col * 19, 20 + row * 22
            cv2.rectangle(kb, (x0, y0), (x0 + 15, y0 + 17), key_colour, -1)
    cv2.rectangle(kb, (80, 150), (176, 220), tuple(int(c) for c in tx.shade(p.c1, 0.8)), -1)
    p.boxed(box(w, d, t).moved((0, 0, t / 2)), p.tile(kb), shell, facing=UP)
    screen = tx.solid(tx.rgb("black"), p.rng, grain=2)
    wall = cv2.resize(tx.pattern("camouflage", tx.rgb("navy"), tx.rgb("teal"), p.rng), (216, 200))
    screen[28:228, 20:236] = wall
    lid_back = p.body(0.5, 0.5)
    angle = np.deg2rad(p.rng.uniform(100, 118))
    lid = box(w, d, 0.007)
    front, rest = split_facing(lid, UP)
    back, rest = split_facing(rest, (0, 0, -1))
    for m, tile in ((front, p.tile(screen)), (back, lid_back), (rest, shell)):
        p.add(m.moved((0, d / 2, 0)).moved((0, 0, 0), rot_x(angle)).moved((0, d / 2, t)), tile)


def mug(p: Parts) -> None:
    v = p.look.variant
    r, h = {"mug": (0.042, 0.095), "tall mug": (0.04, 0.13), "travel mug": (0.038, 0.18)}[v]
    r, h = p.j(r), p.j(h)
    body = lathe([r * 0.92, r, r, r * 0.95], [0, 0.004, h * 0.97, h], 28, caps=False)
    p.add(body, p.body(0.75, 0.45))
    p.add(cylinder(r * 0.92, 0.001, 20), p.solid(p.c1))
    inside = p.solid(tx.shade(p.c1, 0.35) if v != "travel mug" else p.c2)
    p.add(cylinder(r * 0.95, 0.001, 20).moved((0, 0, h * 0.93)), inside)
    if v == "travel mug":
        p.add(cylinder(r * 1.02, 0.025, 24).moved((0, 0, h)), p.solid(p.c2))
    else:
        p.add(torus(h * 0.3, 0.007, np.pi, 14, 6).moved((0, 0, 0), rot_y(np.pi / 2)).moved((r - 0.003, 0, h * 0.52)),
              p.solid(p.c2))


def shoes(p: Parts) -> None:
    v = p.look.variant
    length = p.j(0.27, 0.4)
    upper, sole = p.body(0.25, 0.5), p.solid(p.c2)
    for side in (-1, 1):
        x = side * 0.06
        p.add(box(0.095, length, 0.025).moved((x, 0, 0.0125)), sole)
        p.add(ellipsoid(0.045, length * 0.47, 0.055, 18).moved((x, 0.005, 0.03)), upper)
        if v == "boots":
            p.add(cylinder(0.042, 0.14, 18).scaled((1, 1.2, 1)).moved((x, length * 0.22, 0.03)), upper)
        else:
            p.add(cylinder(0.036, 0.05, 16).scaled((1, 1.3, 1)).moved((x, length * 0.25, 0.04)), upper)


def teddy_bear(p: Parts) -> None:
    s = p.j({"teddy bear": 1.0, "small teddy bear": 0.7, "big teddy bear": 1.4}[p.look.variant])
    fur = p.tile(tx.fabric(p.rng, p.c1))
    belly = tx.fabric(p.rng, tx.shade(p.c1, 1.25) + 20)
    if p.look.photo:
        tx.photo(belly, prints.image(p.look.photo), (0.75, 0.5), 0.3)
    light = p.tile(belly)
    dark = p.solid(tx.rgb("black"), grain=2)
    bow = p.solid(p.c2)
    p.add(ellipsoid(0.075 * s, 0.065 * s, 0.09 * s, 20).moved((0, 0, 0.09 * s)), light)
    p.add(ellipsoid(0.065 * s, 0.06 * s, 0.06 * s, 20).moved((0, 0, 0.225 * s)), fur)
    p.add(ellipsoid(0.025 * s, 0.02 * s, 0.02 * s, 10).moved((0, -0.055 * s, 0.215 * s)), light)
    p.add(ellipsoid(0.008 * s, 0.006 * s, 0.006 * s, 6).moved((0, -0.076 * s, 0.222 * s)), dark)
    for side in (-1, 1):
        p.add(ellipsoid(0.022 * s, 0.012 * s, 0.022 * s, 10).moved((side * 0.048 * s, 0, 0.28 * s)), fur)
        p.add(ellipsoid(0.007 * s, 0.004 * s, 0.007 * s, 6).moved((side * 0.022 * s, -0.056 * s, 0.24 * s)), dark)
        p.add(ellipsoid(0.025 * s, 0.025 * s, 0.055 * s, 12).moved((side * 0.08 * s, -0.015 * s, 0.1 * s),
                                                                  rot_y(side * 0.5)), fur)
        p.add(ellipsoid(0.03 * s, 0.05 * s, 0.028 * s, 12).moved((side * 0.045 * s, -0.05 * s, 0.028 * s)), fur)
        p.add(ellipsoid(0.022 * s, 0.01 * s, 0.015 * s, 8).moved((side * 0.022 * s, -0.062 * s, 0.172 * s)), bow)


def toy(p: Parts) -> None:  # noqa: C901 - one branch per toy variant; split up, a toy would be drawn in 5 places
    v = p.look.variant
    main, other = p.body(0.5, 0.5), p.solid(p.c2)
    dark = p.solid(tx.rgb("black"))
    s = p.j(1.0, 2)
    if v == "toy car":
        L, W = 0.16 * s, 0.08 * s
        p.add(box(W, L, 0.04 * s).moved((0, 0, 0.035 * s)), main)
        p.add(box(W * 0.85, L * 0.5, 0.035 * s).moved((0, 0.01 * s, 0.072 * s)), other)
        for sx in (-1, 1):
            for sy in (-1, 1):
                wheel = cylinder(0.02 * s, 0.014 * s, 14).moved((0, 0, -0.007 * s), rot_y(np.pi / 2))
                p.add(wheel.moved((sx * W / 2, sy * L * 0.32, 0.02 * s)), dark)
    elif v == "toy robot":
        p.boxed(box(0.07 * s, 0.045 * s, 0.08 * s).moved((0, 0, 0.1 * s)), main, other)
        p.add(box(0.05 * s, 0.045 * s, 0.045 * s).moved((0, 0, 0.165 * s)), other)
        for sx in (-1, 1):
            p.add(box(0.022 * s, 0.025 * s, 0.06 * s).moved((sx * 0.018 * s, 0, 0.03 * s)), other)
            p.add(box(0.018 * s, 0.02 * s, 0.065 * s).moved((sx * 0.045 * s, 0, 0.105 * s)), other)
            p.add(ellipsoid(0.007 * s, 0.003 * s, 0.007 * s, 6).moved((sx * 0.012 * s, -0.023 * s, 0.17 * s)), dark)
        p.add(cylinder(0.003 * s, 0.025 * s, 6).moved((0, 0, 0.187 * s)), dark)
    elif v == "rubber duck":
        p.add(ellipsoid(0.06 * s, 0.075 * s, 0.045 * s, 18).moved((0, 0.01 * s, 0.045 * s)), main)
        p.add(ellipsoid(0.035 * s, 0.035 * s, 0.035 * s, 16).moved((0, -0.035 * s, 0.11 * s)), main)
        p.add(ellipsoid(0.018 * s, 0.022 * s, 0.007 * s, 8).moved((0, -0.07 * s, 0.105 * s)), other)
        for sx in (-1, 1):
            p.add(ellipsoid(0.005 * s, 0.004 * s, 0.005 * s, 6).moved((sx * 0.015 * s, -0.064 * s, 0.122 * s)), dark)
    elif v == "toy rocket":
        p.add(lathe([0.03 * s, 0.03 * s, 0.025 * s, 0.0], [0, 0.14 * s, 0.18 * s, 0.21 * s], 20), main)
        for k in range(3):
            fin = box(0.004 * s, 0.04 * s, 0.05 * s).moved((0, 0.045 * s, 0.025 * s))
            p.add(fin.moved((0, 0, 0), rot_z(2 * np.pi * k / 3)), other)
    else:
        p.add(cylinder(0.05 * s, 0.015 * s, 20), other)
        p.add(cylinder(0.008 * s, 0.15 * s, 10), other)
        colours = ["red", "orange", "yellow", "green", "blue"]
        for k, name in enumerate(colours):
            r = (0.045 - k * 0.006) * s
            ring = torus(r, 0.012 * s, 2 * np.pi, 20, 8).moved((0, 0, 0), rot_x(np.pi / 2))
            p.add(ring.moved((0, 0, (0.027 + 0.024 * k) * s)), main if k == 0 else p.solid(tx.rgb(name)))


def visor(p: Parts) -> None:
    r = p.j(0.09, 0.3)
    band = p.body(0.75, 0.5)
    p.add(lathe([r, r], [0, 0.035], 28, caps=False).scaled((1, 1.15, 1)), band)
    brim = ellipsoid(r * 1.05, r * 0.9, 0.005, 24).moved((0, -r * 0.75, 0.006))
    p.add(brim, p.solid(p.c1))
    p.add(flat_ring(r * 0.98, r * 1.0, 0.036).scaled((1, 1.15, 1)), p.solid(p.c2))


def wallet(p: Parts) -> None:
    v = p.look.variant
    w, d, t = {"bifold wallet": (0.115, 0.09, 0.018), "zip wallet": (0.19, 0.1, 0.025),
               "card holder": (0.1, 0.07, 0.008)}[v]
    w, d = p.j(w, 0.5), p.j(d, 0.5)
    leather = tx.fabric(p.rng, p.c1)
    cv2.rectangle(leather, (14, 14), (242, 242), tuple(int(c) for c in p.c2), 2, cv2.LINE_4)
    if v == "zip wallet":
        cv2.line(leather, (10, 40), (246, 40), (200, 200, 205), 5)
    if p.look.photo:
        tx.photo(leather, prints.image(p.look.photo), (0.5, 0.5), 0.6)
    if p.look.word:
        tx.text(leather, p.look.word, tx.rgb("gold"), (0.5, 0.5), 0.5)
    p.boxed(box(w, d, t).moved((0, 0, t / 2)), p.tile(leather), p.tile(tx.fabric(p.rng, p.c1)), facing=UP)


def watch(p: Parts) -> None:
    v = p.look.variant
    r = p.j(0.02, 0.3)
    case = p.solid(p.c1, grain=10)
    dial = tx.solid(tx.rgb("white" if p.look.colour in ("black", "dark grey") else "black"), p.rng, grain=2)
    ink = tuple(int(c) for c in tx.contrasting(dial[128, 128].astype(float)))
    if v == "wristwatch":
        for k in range(12):
            a = 2 * np.pi * k / 12
            cv2.line(dial, (int(128 + 95 * np.cos(a)), int(128 + 95 * np.sin(a))),
                     (int(128 + 115 * np.cos(a)), int(128 + 115 * np.sin(a))), ink, 6)
        cv2.line(dial, (128, 128), (128, 50), ink, 7)
        cv2.line(dial, (128, 128), (185, 150), ink, 7)
        top = cylinder(r, 0.011, 24)
    else:
        tx.text(dial, "12:45" if v == "digital watch" else "09:30", ink, (0.5, 0.5), 0.8)
        top = box(2 * r, 2.3 * r, 0.011).moved((0, 0, 0.0055))
    face, rest = split_facing(top, UP)
    p.add(face.moved((0, 0, 0.004)), p.tile(dial))
    p.add(rest.moved((0, 0, 0.004)), case)
    strap = p.solid(p.c2, grain=8)
    for sy in (-1, 1):
        p.add(box(0.02, 0.09, 0.004).moved((0, sy * (r + 0.04), 0.002)), strap)


BUILDERS: dict[str, Callable[[Parts], None]] = {
    "backpack": backpack, "bag": bag, "ball": ball, "book": book, "camera": camera, "cellphone": cellphone,
    "eyeglasses": eyeglasses, "hat": hat, "headphones": headphones, "keys": keys, "laptop": laptop, "mug": mug,
    "shoes": shoes, "teddy bear": teddy_bear, "toy": toy, "visor": visor, "wallet": wallet, "watch": watch,
}


# The smallest objects are drawn larger than life: at real size a key ring or a watch seen by a camera
# 1.31 m high, standing at the table, covers 1,000-1,500 pixels of a 640 x 360 frame, too few for any
# matcher's features; scaled up to this side area they cover 2,000 or more where the walk stops.
MIN_SIDE_AREA = 0.015  # m^2


def build(spec: ObjectSpec) -> tuple[Mesh, np.ndarray]:
    """The instance's mesh (resting on z = 0, centred in x and y) and its RGB texture atlas."""
    parts = Parts(spec.look, np.random.default_rng(spec.geometry_seed), CATEGORY_SPECS[spec.category].spread)
    BUILDERS[spec.category](parts)
    mesh, atlas = parts.assemble()
    return mesh.scaled(max(1.0, float(np.sqrt(MIN_SIDE_AREA / mesh.side_area())))), atlas
