"""A small frame-set built from real photos that ship inside scikit-image's wheel.

Synthetic renders say little about whether a pretrained network recognises a real object;
this set does, with nothing downloaded. Objects (a cup, a motorcycle, a rocket, a mission
patch, a cat, a helmet) are cut out of scikit-image's bundled sample photos with GrabCut
started from hand-set polygons (``recolour_photos``), then pasted at other scales, rotations
and positions onto other real photos and textures. Each target has a same-category look-alike: a recoloured
copy, or for the rocket another instance of the kind (the shuttle model in ``astronaut``).

Every frame's instance mask is the exact union of the pasted masks (later pastes occlude
earlier ones), so ground truth is exact. Output depends on the seed only: GrabCut runs
with OpenCV's RNG seeded, and all placement is drawn from generators seeded by name.

Limits worth knowing: reference views are 2-D warps of the same photo the frames are cut
from (a real deployment photographs the object again), so this set measures recognition
under scale, rotation, background and colour change, not under a new viewpoint.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pin_match.data.agent import FRAME_HEIGHT, FRAME_WIDTH
from pin_match.data.compose import (
    paste,
    room_crop,
    rotate_hue,
    scale_brightness,
    stable_seed,
)
from pin_match.data.frameset import FrameSet
from pin_match.data.sources.catalogue import DataSource, register
from pin_match.data.sources.recolour_photos import BACKGROUNDS, RecolourSetError, cutout_rgba
from pin_match.data.writer import FrameSetWriter

RECOLOUR_VERSION = 1
DEFAULT_SEED = 0
# per episode: frames with the target, with only its look-alike, with other objects only, with nothing
FRAME_KINDS = ("target",) * 5 + ("lookalike",) * 3 + ("other",) * 2 + ("empty",) * 2


@dataclass(frozen=True)
class RealObject:
    """One object of the set: its cutout, an optional recolouring and what a user would say about it."""

    object_id: str
    category: str
    cutout: str
    descriptions: tuple[str, str, str]
    hue: int = 0  # OpenCV hue units (0..179) added to every pixel: a recoloured copy
    tint: tuple[float, float, float] | None = None  # RGB gains for near-grey objects a hue shift cannot recolour
    second_view: str | None = None  # a real second photo of the same object, used as reference view 1


OBJECTS: tuple[RealObject, ...] = (
    RealObject("cup_red", "cup", "cup", ("a red espresso cup on a red saucer with a spoon",
                                         "small glossy red coffee cup with a white inside",
                                         "red porcelain espresso cup and saucer")),
    RealObject("cup_blue", "cup", "cup", ("a blue espresso cup on a blue saucer with a spoon",
                                          "small glossy blue coffee cup with a white inside",
                                          "blue porcelain espresso cup and saucer"), hue=105),
    RealObject("motorcycle_red", "motorcycle", "motorcycle", ("a red Yamaha motorcycle with a black seat",
                                                              "red cruiser motorbike with chrome engine",
                                                              "old red motorcycle with spoked wheels"),
               second_view="motorcycle_right"),
    RealObject("motorcycle_blue", "motorcycle", "motorcycle", ("a blue Yamaha motorcycle with a black seat",
                                                               "blue cruiser motorbike with chrome engine",
                                                               "old blue motorcycle with spoked wheels"),
               hue=110, second_view="motorcycle_right"),
    RealObject("rocket_falcon", "rocket", "rocket", ("a tall white rocket with a rounded nose cone",
                                                      "white launch rocket standing upright",
                                                      "slim white rocket with a small logo near the top")),
    RealObject("rocket_shuttle", "rocket", "shuttle", ("a space shuttle model on an orange fuel tank",
                                                        "white shuttle with boosters and a brown tank",
                                                        "model of the space shuttle stack")),
    RealObject("patch_purple", "patch", "patch", ("a round purple mission patch with a shuttle",
                                                   "embroidered circular badge, purple and white",
                                                   "purple space mission patch with text around the rim")),
    RealObject("patch_green", "patch", "patch", ("a round green mission patch with a shuttle",
                                                  "embroidered circular badge, green and white",
                                                  "green space mission patch with text around the rim"), hue=75),
    RealObject("cat_tabby", "cat", "cat", ("a tabby cat with green eyes",
                                           "close-up of a brown striped cat face",
                                           "tabby cat with a pink nose")),
    RealObject("cat_grey", "cat", "cat", ("a grey blue cat with green eyes",
                                          "close-up of a bluish striped cat face",
                                          "grey cat with a lilac nose"), hue=100),
    RealObject("helmet_black", "helmet", "helmet", ("a black space helmet with a white shell",
                                                     "astronaut helmet with a dark glossy visor",
                                                     "white helmet with a black visor")),
    RealObject("helmet_gold", "helmet", "helmet", ("a space helmet with a gold visor",
                                                    "astronaut helmet with a golden shell",
                                                    "yellowish helmet with a gold tinted visor"),
               tint=(1.35, 1.05, 0.45)),
)
TARGETS = ("cup_red", "motorcycle_red", "rocket_falcon", "patch_purple", "cat_tabby", "helmet_black")


def recolour(rgba: np.ndarray, hue: int = 0, tint: tuple[float, float, float] | None = None) -> np.ndarray:
    """A recoloured copy: hue rotated by ``hue`` (OpenCV units) and/or RGB gains; alpha unchanged."""
    rgb = rgba[..., :3]
    if hue:
        rgb = rotate_hue(rgb, hue)
    if tint is not None:
        rgb = scale_brightness(rgb, tint)
    return np.dstack([rgb, rgba[..., 3]])


def object_rgba(obj: RealObject, cutout: str | None = None) -> np.ndarray:
    return recolour(cutout_rgba(cutout or obj.cutout), obj.hue, obj.tint)


# ------------------------------------------------------------------ geometry
def warp_rgba(rgba: np.ndarray, size: float, angle: float, squeeze: float = 1.0) -> np.ndarray:
    """Scale so the longer side is ``size`` px, compress one side by ``squeeze`` (a turn in depth), rotate.

    Returns a new RGBA on a canvas that holds the whole warped object; alpha stays binary
    (warped with linear interpolation, then thresholded at half), so a paste is exact.
    """
    h, w = rgba.shape[:2]
    s = size / max(h, w)
    src = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    sq = (1.0 - squeeze) * h * s / 2
    dst = np.float32([[0, 0], [w * s, sq], [w * s, h * s - sq], [0, h * s]])
    rot = cv2.getRotationMatrix2D((0.0, 0.0), angle, 1.0)
    pts = np.hstack([dst, np.ones((4, 1), np.float32)]) @ rot.T
    lo = pts.min(0)
    pts = (pts - lo).astype(np.float32)
    out_w, out_h = int(np.ceil(pts[:, 0].max())) + 1, int(np.ceil(pts[:, 1].max())) + 1
    m = cv2.getPerspectiveTransform(src, pts)
    rgb = cv2.warpPerspective(rgba[..., :3], m, (out_w, out_h), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
    alpha = cv2.warpPerspective(rgba[..., 3], m, (out_w, out_h), flags=cv2.INTER_LINEAR, borderValue=0)
    alpha = np.where(alpha >= 128, 255, 0).astype(np.uint8)
    rgb[alpha == 0] = 0
    return np.dstack([rgb, alpha])


def reference_views(obj: RealObject) -> list[np.ndarray]:
    """Three RGBA views: the photo as cut, a turned view (or a real second photo), a tilted darker view."""
    base = object_rgba(obj)
    size = float(max(base.shape[:2]))
    turned = object_rgba(obj, obj.second_view) if obj.second_view else warp_rgba(base, size, 0.0, squeeze=0.75)
    tilted = scale_brightness(warp_rgba(base, size * 0.9, 12.0), 0.85)
    return [base, turned, tilted]


@dataclass(frozen=True)
class Placement:
    """One pasted object: id, longer side in px, in-plane angle, depth squeeze, brightness, top-left corner."""

    object_id: str
    size: float
    angle: float
    squeeze: float
    gain: float
    x: int
    y: int


def placed(p: Placement) -> np.ndarray:
    """The RGBA of a placement (warped, brightness applied), before it is positioned."""
    return scale_brightness(warp_rgba(object_rgba(OBJECT_BY_ID[p.object_id]), p.size, p.angle, p.squeeze), p.gain)


def compose_frame(background: np.ndarray, placements: list[Placement]) -> tuple[np.ndarray, np.ndarray]:
    """Paste in order (later occludes earlier); mask value k+1 marks placement k's visible pixels."""
    image = background.copy()
    mask = np.zeros(background.shape[:2], np.uint16)
    for k, p in enumerate(placements):
        paste(image, mask, placed(p), p.x, p.y, k + 1)
    return image, mask


def _overlap(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> float:
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return max(w, 0) * max(h, 0) / ((a[2] - a[0]) * (a[3] - a[1]))


def plan_frame(object_ids: list[str], rng: np.random.Generator) -> list[Placement]:
    """Sizes, angles and positions for the objects of one frame, inside the frame, overlapping little."""
    out: list[Placement] = []
    boxes: list[tuple[int, int, int, int]] = []
    for oid in object_ids:
        size = float(rng.uniform(110, 290))
        angle = float(rng.uniform(-30, 30))
        squeeze = float(rng.uniform(0.75, 1.0))
        gain = float(rng.uniform(0.8, 1.15))
        h, w = warp_rgba(object_rgba(OBJECT_BY_ID[oid]), size, angle, squeeze).shape[:2]
        for _ in range(30):
            x = int(rng.integers(0, max(FRAME_WIDTH - w, 0) + 1))
            y = int(rng.integers(0, max(FRAME_HEIGHT - h, 0) + 1))
            box = (x, y, x + w, y + h)
            if all(_overlap(box, b) < 0.2 and _overlap(b, box) < 0.2 for b in boxes):
                break
        boxes.append(box)
        out.append(Placement(oid, size, angle, squeeze, gain, x, y))
    return out


OBJECT_BY_ID = {o.object_id: o for o in OBJECTS}


def lookalike_of(target_id: str) -> str:
    t = OBJECT_BY_ID[target_id]
    return next(o.object_id for o in OBJECTS if o.category == t.category and o.object_id != target_id)


def episode_objects(target_id: str, rng: np.random.Generator) -> tuple[str, list[str]]:
    """The target's look-alike and three objects of other categories (other targets or look-alikes)."""
    category = OBJECT_BY_ID[target_id].category
    others = [o.object_id for o in OBJECTS if o.category != category]
    return lookalike_of(target_id), [others[i] for i in sorted(rng.choice(len(others), 3, replace=False))]


def frame_objects(kind: str, target: str, lookalike: str, others: list[str],
                  rng: np.random.Generator) -> list[str]:
    """Which objects a frame of ``kind`` shows (see FRAME_KINDS)."""
    if kind == "empty":
        return []
    extra = [others[i] for i in rng.choice(len(others), int(rng.integers(0, 3)), replace=False)]
    if kind == "target":
        chosen = [target, *extra]
        if rng.random() < 0.4:
            chosen.append(lookalike)
    elif kind == "lookalike":
        chosen = [lookalike, *extra]
    else:
        chosen = extra or [others[int(rng.integers(len(others)))]]
    return [chosen[i] for i in rng.permutation(len(chosen))]


def episode_plan(seed: int, target: str) -> tuple[str, list[str], list[tuple[np.ndarray, list[Placement]]]]:
    """An episode's look-alike, other objects and, per frame, the background and placements.

    Everything is drawn from one generator seeded by (seed, target), so tests can rebuild
    exactly what ``build`` pasted.
    """
    rng = np.random.default_rng(stable_seed(seed, "realset", target))  # the set's old name: same seeds, same bytes
    lookalike, others = episode_objects(target, rng)
    bg_names = sorted(BACKGROUNDS)
    frames = []
    for kind in FRAME_KINDS:
        ids = frame_objects(kind, target, lookalike, others, rng)
        photo = BACKGROUNDS[bg_names[int(rng.integers(len(bg_names)))]]()
        bg = room_crop(photo, rng, zoom=float(rng.uniform(0.7, 1.0)))
        frames.append((bg, plan_frame(ids, rng)))
    return lookalike, others, frames


def camera_noise(image: np.ndarray, seed: int, episode_id: str, step: int) -> np.ndarray:
    """Mild sensor noise over the whole composite, so pasted edges are not the only crisp pixels."""
    noise = np.random.default_rng(stable_seed(seed, "noise", episode_id, step)).normal(0, 2.0, image.shape)
    return np.clip(np.round(image + noise), 0, 255).astype(np.uint8)


def build(out: str | Path, *, seed: int = DEFAULT_SEED, targets: tuple[str, ...] = TARGETS,
          overwrite: bool = False) -> FrameSet:
    """Write the real-photo frame-set to ``out`` and return it loaded.

    One episode ``real_<target>`` per target (split ``val``: it is a test set), frames as in
    ``FRAME_KINDS``: 5 with the target, 3 with only its same-category look-alike, 2 with
    other objects, 2 with nothing. Holds the objects the episodes use. Byte-identical for
    the same seed; an episode does not depend on which other targets are built.
    """
    unknown = [t for t in targets if t not in OBJECT_BY_ID]
    if unknown:
        raise RecolourSetError(f"unknown real-photo target(s) {unknown}; known: {list(TARGETS)}")
    # "generator": the name these frame-sets have always recorded (the module's old path), kept so they stay
    # byte-identical
    provenance = dict(generator="pin_match.data.realset", version=RECOLOUR_VERSION, seed=seed, targets=list(targets),
                      photos="scikit-image bundled sample data", frame_size=[FRAME_HEIGHT, FRAME_WIDTH])
    writer = FrameSetWriter(out, Path(out).name, overwrite=overwrite, provenance=provenance)
    with writer:
        plans = {t: episode_plan(seed, t) for t in targets}
        used = {oid for t, (lookalike, others, _) in plans.items() for oid in (t, lookalike, *others)}
        for obj in OBJECTS:
            if obj.object_id in used:
                writer.add_object(obj.object_id, obj.category, "val", reference_views(obj), list(obj.descriptions))
        for target, (lookalike, others, frames) in plans.items():
            episode_id = f"real_{target}"
            writer.add_episode(episode_id, "val", f"real_scene_{target}", target, [lookalike, *others])
            roles = writer.roles(episode_id)
            for step, (bg, placements) in enumerate(frames):
                image, mask = compose_frame(bg, placements)
                writer.add_frame(episode_id, step, camera_noise(image, seed, episode_id, step), mask,
                                 {k + 1: (p.object_id, roles[p.object_id]) for k, p in enumerate(placements)})
        return writer.close()


def _make(out: Path, *, variant: str, seed: int, src: Path | None, overwrite: bool) -> FrameSet:
    return build(out, seed=seed, overwrite=overwrite)


SOURCE = register(DataSource(
    name="recolour",
    summary="6 objects cut out of scikit-image's bundled photos, pasted onto real backgrounds; each target's "
            "look-alike is its recoloured copy (needs scikit-image; 72 val frames)",
    licence="scikit-image's bundled sample photos, each under the terms its skimage.data function states (most CC0 "
            "or public domain); read from the installed scikit-image, not shipped by pin_match",
    variants=("default",), make=_make))
