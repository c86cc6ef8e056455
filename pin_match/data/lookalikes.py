"""A development frame-set of real look-alikes: several real instances per category, real photos of each.

The recolour set (``pin_match.data.realset``) rewards colour: its look-alikes are the target's own
photo recoloured. This set's look-alikes are other physical objects of the same kind, photographed
on their own, so a default chosen on it is chosen on the problem PIN poses.

A source folder (``SRC``) holds the photos, one automatic mask per photo and where each came from:

    SRC/photos.csv   photo_id, instance_id, category, file, mask, source, source_path, licence
                     (optional: split, use)
    SRC/rooms.csv    room_id, file, source, source_path, licence
    SRC/<file>       the photos and room photos as downloaded; SRC/<mask>: 8-bit, 255 = object

``prepare_core50`` (and ``pin_match.data.grocery.prepare_grocery``) write it from public
repositories (see docs/lookalike-set.md); ``build`` turns it into a frame-set in one of two variants:

- ``shot``: the photo is the frame (letterboxed into the 640x360 portrait frame, grey bars), so
  the object keeps its real surroundings, hand and lighting;
- ``pasted``: the object is cut out with its mask and pasted into a real indoor room photo.

One episode per target instance that has a same-category look-alike and at least two photos: its
3 reference views come from its first photos (RGBA, alpha = mask), its frames are its other photos,
every photo of its same-category look-alikes, a few other-category photos and empty rooms.
Instances are split train/val inside each category, so a val episode's look-alikes are val
instances too. Two optional columns let a source fix what the rules above would choose: ``split``
(the instance's split, on every photo of the source) and ``use`` (``reference``: the photo is one
of its instance's reference views and never a frame; an instance with such photos takes its
references from them alone). Everything is drawn from generators seeded by name: the same SRC and seed give the
same bytes.
"""

from __future__ import annotations

import csv
import math
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pin_match import atomic
from pin_match.data.frameset import SPLITS, FrameSet
from pin_match.data.realset import FRAME_HEIGHT, FRAME_WIDTH, stable_seed
from pin_match.data.writer import FrameSetWriter
from pin_match.errors import PinMatchError

LOOKALIKES_VERSION = 1
# the CORe50 photos, their masks and the TUM rooms, as prepare_core50 wrote them (licences: NOTICE.md there)
PACKAGED_SRC = Path(__file__).resolve().with_name("lookalike_src")
VARIANTS = ("shot", "pasted")
N_REFERENCE_PHOTOS = 3
N_OTHER_FRAMES = 4
N_EMPTY_FRAMES = 3
LETTERBOX_GREY = 114
PHOTO_COLUMNS = ("photo_id", "instance_id", "category", "file", "mask", "source", "source_path", "licence")
ROOM_COLUMNS = ("room_id", "file", "source", "source_path", "licence")
OPTIONAL_PHOTO_COLUMNS = ("split", "use")
REFERENCE_USE = "reference"

# CORe50 (Lomonaco & Maltoni, CoRL 2017): objects 1-50, five instances per category in this order
CORE50_CATEGORIES = ("plug_adapter", "mobile_phone", "scissors", "light_bulb", "can", "glasses", "ball", "marker",
                     "cup", "remote_control")
CORE50_LICENCE = "CC BY 4.0 (CORe50, Lomonaco & Maltoni 2017; licence file: vlomonaco/core50 LICENSE)"
CORE50_SOURCE = "github:giacomobartoli/core50_segmentation"
TUM_LICENCE = "CC BY 4.0 (TUM RGB-D benchmark, Sturm et al. 2012; frames from fr3/long_office_household)"
TUM_SOURCE = "github:gaoxiang12/slambook2"
TUM_FRAMES = tuple(f"ch11/data/{k}.png" for k in range(1, 11))


class LookalikeError(PinMatchError, ValueError):
    """The look-alike source folder is missing, malformed or too small to build episodes from."""


@dataclass(frozen=True)
class Photo:
    photo_id: str
    instance_id: str
    category: str
    file: str
    mask: str
    split: str = ""  # the instance's split when the source fixes it; "" = the hash rule of instance_splits
    use: str = ""  # REFERENCE_USE: a reference view only, never a frame; "" = either, by the plan's rule


# ------------------------------------------------------------------ masks
def object_mask(rgb: np.ndarray, iterations: int = 5) -> np.ndarray:
    """An automatic mask (uint8, 255 = object) of the one object near the centre of a photo.

    Why this recipe: the photos centre one hand-held object, so GrabCut is seeded with the
    border as sure background and the middle as probable object; skin-coloured pixels (YCrCb
    box of Chai & Ngan 1999) start as probable background so the holding hand mostly drops out.
    The largest connected piece is kept and its holes filled. When GrabCut keeps nothing, the
    seed's middle minus skin is the mask. Deterministic (OpenCV's RNG seeded).
    """
    h, w = rgb.shape[:2]
    seed = np.full((h, w), cv2.GC_PR_BGD, np.uint8)
    by, bx = max(h // 10, 2), max(w // 10, 2)
    seed[by:h - by, bx:w - bx] = cv2.GC_PR_FGD
    ycrcb = cv2.cvtColor(rgb, cv2.COLOR_RGB2YCrCb)
    skin = (ycrcb[..., 1] >= 138) & (ycrcb[..., 1] <= 173) & (ycrcb[..., 2] >= 77) & (ycrcb[..., 2] <= 127)
    seed[skin & (seed == cv2.GC_PR_FGD)] = cv2.GC_PR_BGD
    edge = max(min(h, w) // 32, 1)
    seed[:edge], seed[-edge:], seed[:, :edge], seed[:, -edge:] = (cv2.GC_BGD,) * 4
    fallback = (seed == cv2.GC_PR_FGD).astype(np.uint8)
    cv2.setRNGSeed(0)
    cv2.grabCut(np.ascontiguousarray(rgb[..., ::-1]), seed, None, np.zeros((1, 65)), np.zeros((1, 65)),
                iterations, cv2.GC_INIT_WITH_MASK)
    fg = np.isin(seed, (cv2.GC_FGD, cv2.GC_PR_FGD)).astype(np.uint8)
    fg = cv2.morphologyEx(fg, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n <= 1:
        fg = fallback
        n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    fg = (labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
    holes = cv2.floodFill(fg.copy() * 255, np.zeros((h + 2, w + 2), np.uint8), (0, 0), 255)[1] == 0
    return np.where((fg > 0) | holes, 255, 0).astype(np.uint8)


# ------------------------------------------------------------------ source folder
def prepare_core50(core50_repo: str | Path, rooms_repo: str | Path, out: str | Path, *,
                   overwrite: bool = False) -> Path:
    """Write a source folder from a checkout of the CORe50 sample photos and of the room photos.

    ``core50_repo``: giacomobartoli/core50_segmentation (its ``images/C_<session>_<object>_<frame>.png``,
    128 px crops centred on the object).
    ``rooms_repo``: gaoxiang12/slambook2 (``ch11/data/1..10.png``: TUM RGB-D frames).
    """
    core50_repo, rooms_repo, out = Path(core50_repo), Path(rooms_repo), Path(out)
    # only the 128 px crops: in the repository's 350 px frames (training_images/) the object is small and off
    # centre, and the border-seeded mask takes the wall instead
    sources = sorted((core50_repo / "images").glob("C_*.png"))
    if not sources:
        raise LookalikeError(f"{core50_repo} holds no CORe50 photos (images/C_*.png)")
    rooms = [rooms_repo / f for f in TUM_FRAMES]
    missing = [str(p) for p in rooms if not p.is_file()]
    if missing:
        raise LookalikeError(f"room photos missing: {missing}")
    if out.exists():
        if not overwrite:
            raise LookalikeError(f"{out} already exists: pass overwrite=True to replace it")
        shutil.rmtree(out)
    photo_rows, room_rows = [], []
    for src in sources:
        _, session, obj, frame = src.stem.split("_")
        o = int(obj)
        photo_id = f"core50_s{int(session):02d}_o{o:02d}_{frame}"
        rgb = _read_rgb(src)
        file, mask = f"photos/{photo_id}{src.suffix}", f"masks/{photo_id}.png"
        atomic.write_bytes(out / file, src.read_bytes())
        atomic.write_image(out / mask, object_mask(rgb))
        photo_rows.append(dict(photo_id=photo_id, instance_id=f"core50_o{o:02d}",
                               category=CORE50_CATEGORIES[(o - 1) // 5],
                               file=file, mask=mask, source=CORE50_SOURCE,
                               source_path=str(src.relative_to(core50_repo)), licence=CORE50_LICENCE))
    for k, src in enumerate(rooms, start=1):
        file = f"rooms/tum_fr3_office_{k:02d}.png"
        atomic.write_bytes(out / file, src.read_bytes())
        room_rows.append(dict(room_id=f"tum_fr3_office_{k:02d}", file=file, source=TUM_SOURCE,
                              source_path=str(src.relative_to(rooms_repo)), licence=TUM_LICENCE))
    _write_csv(out / "photos.csv", PHOTO_COLUMNS, photo_rows)
    _write_csv(out / "rooms.csv", ROOM_COLUMNS, room_rows)
    return out


def _write_csv(path: Path, columns: Sequence[str], rows: list[dict]) -> None:
    import io

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic.write_text(path, buf.getvalue())


def _read_csv(path: Path, columns: Sequence[str]) -> list[dict]:
    if not path.is_file():
        raise LookalikeError(f"{path} is missing (a look-alike source folder needs photos.csv and rooms.csv)")
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows or any(c not in rows[0] for c in columns):
        raise LookalikeError(f"{path} needs a header with {list(columns)} and at least one row")
    return rows


def _read_rgb(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise LookalikeError(f"cannot read image {path}")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def _read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray:
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if m is None or m.shape != shape:
        raise LookalikeError(f"mask {path} is missing, unreadable or not the size of its photo {shape}")
    if not (m > 127).any():
        raise LookalikeError(f"mask {path} is empty")
    return (m > 127).astype(np.uint8)


def load_photos(src: str | Path) -> list[Photo]:
    path = Path(src) / "photos.csv"
    photos = [Photo(r["photo_id"], r["instance_id"], r["category"], r["file"], r["mask"], r.get("split") or "",
                    r.get("use") or "") for r in _read_csv(path, PHOTO_COLUMNS)]
    for p in photos:
        if p.split not in ("", *SPLITS) or p.use not in ("", REFERENCE_USE):
            raise LookalikeError(f"{path}: photo {p.photo_id!r} has split {p.split!r} and use {p.use!r} "
                                 f"(split: {' or '.join(SPLITS)} or empty; use: {REFERENCE_USE!r} or empty)")
    return photos


# ------------------------------------------------------------------ plan
@dataclass(frozen=True)
class EpisodePlan:
    episode_id: str
    split: str
    target: str
    reference_photos: tuple[str, ...]
    frames: tuple[tuple[str, str], ...]  # (kind, photo_id or room_id); kind in target, lookalike, other, empty


def instance_splits(photos: Sequence[Photo]) -> dict[str, str]:
    """Inside each category, the first half of the instances (by a stable hash of the id) train, the rest val.

    A source whose photos carry a split keeps it: then every photo must carry one, the same for
    all photos of an instance, so no instance can end up in both splits.
    """
    if any(p.split for p in photos):
        fixed: dict[str, str] = {}
        for p in photos:
            if fixed.setdefault(p.instance_id, p.split) != p.split or not p.split:
                raise LookalikeError(f"photo {p.photo_id!r}: split {p.split!r}, but a source that fixes splits "
                                     f"needs one on every photo, the same for all photos of instance "
                                     f"{p.instance_id!r} ({fixed[p.instance_id]!r})")
        return fixed
    by_cat: dict[str, list[str]] = {}
    for p in photos:
        by_cat.setdefault(p.category, [])
        if p.instance_id not in by_cat[p.category]:
            by_cat[p.category].append(p.instance_id)
    out = {}
    for instances in by_cat.values():
        ranked = sorted(instances, key=lambda i: (stable_seed("split", i), i))
        n_train = math.ceil(len(ranked) / 2)
        out.update({i: ("train" if k < n_train else "val") for k, i in enumerate(ranked)})
    return out


def reference_photos(own: Sequence[Photo], *, keep_one: bool) -> list[Photo]:
    """An instance's reference photos: those marked ``use=reference`` (up to 3), else its first ones.

    Without marked photos the first up to 3 are taken, one fewer than all when ``keep_one``
    (a target keeps a photo for its own frames).
    """
    marked = [p for p in own if p.use == REFERENCE_USE]
    if marked:
        return marked[:N_REFERENCE_PHOTOS]
    return list(own[:min(N_REFERENCE_PHOTOS, len(own) - 1 if keep_one else len(own))])


def plan_episodes(photos: Sequence[Photo], room_ids: Sequence[str], seed: int = 0) -> list[EpisodePlan]:
    """One episode per instance with photos for its references and its frames and a same-split look-alike.

    Look-alikes are the other instances of its category. Photos marked ``use=reference`` are
    never frames, of their own episode or of another.
    """
    split = instance_splits(photos)
    by_instance: dict[str, list[Photo]] = {}
    for p in sorted(photos, key=lambda p: p.photo_id):
        by_instance.setdefault(p.instance_id, []).append(p)
    category = {i: ps[0].category for i, ps in by_instance.items()}
    framed = {i: [p for p in ps if p.use != REFERENCE_USE] for i, ps in by_instance.items()}
    plans = []
    for target, own in sorted(by_instance.items()):
        lookalikes = [i for i in sorted(by_instance) if i != target and category[i] == category[target]
                      and split[i] == split[target]]
        references = reference_photos(own, keep_one=True)
        own_frames = [p for p in framed[target] if p not in references]
        if not references or not own_frames or not lookalikes:
            continue
        rng = np.random.default_rng(stable_seed(seed, "lookalikes", target))
        frames = [("target", p.photo_id) for p in own_frames]
        frames += [("lookalike", p.photo_id) for i in lookalikes for p in framed[i]]
        others = [p.photo_id for i in sorted(by_instance)
                  if category[i] != category[target] and split[i] == split[target] for p in framed[i]]
        frames += [("other", others[k]) for k in sorted(rng.choice(len(others), min(N_OTHER_FRAMES, len(others)),
                                                                   replace=False))]
        frames += [("empty", room_ids[int(k)]) for k in rng.integers(0, len(room_ids), N_EMPTY_FRAMES)]
        order = rng.permutation(len(frames))
        plans.append(EpisodePlan(f"look_{target}", split[target], target, tuple(p.photo_id for p in references),
                                 tuple(frames[k] for k in order)))
    if not plans:
        raise LookalikeError("no instance has a reference photo, a photo for its frames and a same-category "
                             "look-alike in its split: nothing to build")
    return plans


# ------------------------------------------------------------------ images
def cutout(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """RGBA cropped to the mask's box, alpha 0/255, RGB zeroed outside the object."""
    ys, xs = np.nonzero(mask)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    m = mask[y0:y1, x0:x1]
    rgb = rgb[y0:y1, x0:x1] * m[..., None]
    return np.dstack([rgb, m * 255]).astype(np.uint8)


def reference_views(cutouts: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Three views: one per reference photo; fewer photos are filled with their mirror images."""
    views = list(cutouts[:N_REFERENCE_PHOTOS])
    k = 0
    while len(views) < N_REFERENCE_PHOTOS:
        views.append(np.ascontiguousarray(cutouts[k % len(cutouts)][:, ::-1]))
        k += 1
    return views


def letterbox(rgb: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Scale the photo to the frame's width and place it at a random height on grey (the shot variant)."""
    h, w = rgb.shape[:2]
    s = min(FRAME_WIDTH / w, FRAME_HEIGHT / h)
    nw, nh = max(int(round(w * s)), 1), max(int(round(h * s)), 1)
    img = cv2.resize(rgb, (nw, nh), interpolation=cv2.INTER_CUBIC if s > 1 else cv2.INTER_AREA)
    m = cv2.resize(mask, (nw, nh), interpolation=cv2.INTER_NEAREST)
    frame = np.full((FRAME_HEIGHT, FRAME_WIDTH, 3), LETTERBOX_GREY, np.uint8)
    out_mask = np.zeros((FRAME_HEIGHT, FRAME_WIDTH), np.uint16)
    y = int(rng.integers(0, FRAME_HEIGHT - nh + 1))
    x = (FRAME_WIDTH - nw) // 2
    frame[y:y + nh, x:x + nw] = img
    out_mask[y:y + nh, x:x + nw] = m
    return frame, out_mask


def room_frame(room: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A random portrait crop of a room photo (full height), resized to the frame, maybe mirrored."""
    h, w = room.shape[:2]
    cw = min(int(round(h * FRAME_WIDTH / FRAME_HEIGHT)), w)
    x = int(rng.integers(0, w - cw + 1))
    out = cv2.resize(np.ascontiguousarray(room[:, x:x + cw]), (FRAME_WIDTH, FRAME_HEIGHT),
                     interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(out[:, ::-1]) if rng.random() < 0.5 else out


def paste_into(room: np.ndarray, obj: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Paste an RGBA cut-out at a random size (longer side 110-260 px) and position (the pasted variant)."""
    size = float(rng.uniform(110, 260))
    h, w = obj.shape[:2]
    s = size / max(h, w)
    nw, nh = min(max(int(round(w * s)), 1), FRAME_WIDTH), min(max(int(round(h * s)), 1), FRAME_HEIGHT)
    rgba = cv2.resize(obj, (nw, nh), interpolation=cv2.INTER_LINEAR)
    on = rgba[..., 3] >= 128
    gain = float(rng.uniform(0.85, 1.1))
    y = int(rng.integers(0, FRAME_HEIGHT - nh + 1))
    x = int(rng.integers(0, FRAME_WIDTH - nw + 1))
    image = room.copy()
    patch = np.clip(rgba[..., :3].astype(np.float32) * gain, 0, 255).astype(np.uint8)
    image[y:y + nh, x:x + nw][on] = patch[on]
    mask = np.zeros((FRAME_HEIGHT, FRAME_WIDTH), np.uint16)
    mask[y:y + nh, x:x + nw][on] = 1
    return image, mask


def _descriptions(instance_id: str, category: str) -> list[str]:
    name = category.replace("_", " ")
    return [f"a {name}", f"my {name} ({instance_id})", f"a real {name}, photographed in a hand"]


# ------------------------------------------------------------------ build
def build(out: str | Path, src: str | Path | None = None, *, variant: str = "shot", seed: int = 0,
          overwrite: bool = False) -> FrameSet:
    """Write the look-alike frame-set of ``variant`` (``shot`` or ``pasted``) from source folder ``src``.

    Without ``src``, the source folder shipped inside the package (``PACKAGED_SRC``) is used,
    so the set builds on any install, offline.
    """
    if variant not in VARIANTS:
        raise LookalikeError(f"unknown variant {variant!r}; choose one of {list(VARIANTS)}")
    src = Path(src) if src is not None else PACKAGED_SRC
    photos = load_photos(src)
    rooms = _read_csv(src / "rooms.csv", ROOM_COLUMNS)
    room_file = {r["room_id"]: src / r["file"] for r in rooms}
    by_id = {p.photo_id: p for p in photos}
    plans = plan_episodes(photos, sorted(room_file), seed)
    split = instance_splits(photos)

    def image_and_mask(photo_id: str) -> tuple[np.ndarray, np.ndarray]:
        p = by_id[photo_id]
        rgb = _read_rgb(src / p.file)
        return rgb, _read_mask(src / p.mask, rgb.shape[:2])

    used = _objects_used(plans, by_id)
    own_photos: dict[str, list[Photo]] = {}
    for p in sorted(photos, key=lambda p: p.photo_id):
        own_photos.setdefault(p.instance_id, []).append(p)
    provenance = dict(generator="pin_match.lookalikes", version=LOOKALIKES_VERSION, variant=variant, seed=seed,
                      source=str(src.name), photos=len(photos), rooms=len(rooms),
                      frame_size=[FRAME_HEIGHT, FRAME_WIDTH])
    writer = FrameSetWriter(out, Path(out).name, overwrite=overwrite, provenance=provenance, image_ext=".png")
    with writer:
        for inst in sorted(used):
            ref_ids = used[inst] or tuple(p.photo_id for p in reference_photos(own_photos[inst], keep_one=False))
            cut = [cutout(*image_and_mask(pid)) for pid in ref_ids]
            category = own_photos[inst][0].category
            writer.add_object(inst, category, split[inst], reference_views(cut), _descriptions(inst, category))
        for plan in plans:
            distractors = sorted({by_id[pid].instance_id for kind, pid in plan.frames
                                  if kind in ("lookalike", "other")})
            writer.add_episode(plan.episode_id, plan.split, f"lookalike_{variant}_{plan.target}", plan.target,
                               distractors)
            roles = writer.roles(plan.episode_id)
            for step, (kind, item) in enumerate(plan.frames):
                rng = np.random.default_rng(stable_seed(seed, variant, plan.episode_id, step))
                if kind == "empty":
                    image = room_frame(_read_rgb(room_file[item]), rng)
                    writer.add_frame(plan.episode_id, step, image, np.zeros(image.shape[:2], np.uint16), {})
                    continue
                image, frame_mask = _object_frame(*image_and_mask(item), variant, room_file, rng)
                inst = by_id[item].instance_id
                writer.add_frame(plan.episode_id, step, image, frame_mask, {1: (inst, roles[inst])})
        return writer.close()


def _objects_used(plans: Sequence[EpisodePlan], by_id: dict[str, Photo]) -> dict[str, tuple[str, ...]]:
    """Every instance the episodes show: targets with their reference photos, distractors with none chosen yet."""
    used: dict[str, tuple[str, ...]] = {}
    for plan in plans:
        used[plan.target] = plan.reference_photos
        for kind, pid in plan.frames:
            if kind in ("lookalike", "other"):
                used.setdefault(by_id[pid].instance_id, ())
    return used


def _object_frame(rgb: np.ndarray, mask: np.ndarray, variant: str, room_file: dict[str, Path],
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A photo as the frame (``shot``), or its object pasted into a room (``pasted``); with the object's mask."""
    if variant == "shot":
        return letterbox(rgb, mask, rng)
    room = room_frame(_read_rgb(room_file[sorted(room_file)[int(rng.integers(len(room_file)))]]), rng)
    return paste_into(room, cutout(rgb, mask), rng)


def summary(src: str | Path) -> dict[str, dict[str, int]]:
    """Photos per instance, grouped by category (what the set holds, for the docs and the report)."""
    out: dict[str, dict[str, int]] = {}
    for p in load_photos(src):
        out.setdefault(p.category, {}).setdefault(p.instance_id, 0)
        out[p.category][p.instance_id] += 1
    return out
