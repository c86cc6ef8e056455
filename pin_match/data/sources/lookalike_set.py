"""A development frame-set of real look-alikes: several real instances per category, real photos of each.

The recolour set (``pin_match.data.sources.recolour``) rewards colour: its look-alikes are the target's own
photo recoloured. This set's look-alikes are other physical objects of the same kind, photographed
on their own, so a default chosen on it is chosen on the problem PIN poses.

A source folder (its layout: ``pin_match.data.sources.photo_folder``) holds real photos, their
masks and empty room photos. The sources ``core50`` (shipped), ``grocery``, ``myvlm`` and ``twins``
write one (see docs/lookalike-set.md); ``build`` turns it into a frame-set in one of three variants:

- ``shot``: the photo is the frame (letterboxed into the 640x360 portrait frame, grey bars), so
  the object keeps its real surroundings, hand and lighting;
- ``pasted``: the object is cut out with its mask and pasted into a real indoor room photo;
- ``walk``: pasted, as a walk through one room that meets each object once, in an order drawn
  without knowing which is the target (``walk_plan``): an object's photos one after the other,
  the target's each at ``APPROACH_DISTANCES_M``, far to near, as the agent walks up to it; and
  the splits of ``balanced_splits``, so each split has its share of the instances that can be
  targets (the demo's real set);
- ``approach``: as ``walk``, but the walk ends at the target (the look-alikes, other objects and
  empty views first): a stress test of PIN's first match, which meets every look-alike before
  the target; a rule that waits would be told where the target is.

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

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from pin_match.data.agent import FOCAL_PX, FRAME_HEIGHT, FRAME_WIDTH
from pin_match.data.compose import (
    cutout,
    letterbox,
    paste,
    room_crop,
    scale_brightness,
    stable_seed,
)
from pin_match.data.csv_rows import read_rows
from pin_match.data.frameset import FrameSet
from pin_match.data.images import read_image, read_object_mask
from pin_match.data.sources.photo_folder import (
    PACKAGED_SRC,
    REFERENCE_USE,
    ROOM_COLUMNS,
    LookalikeError,
    Photo,
    balanced_splits,
    instance_splits,
    load_photos,
)
from pin_match.data.writer import FrameSetWriter

LOOKALIKES_VERSION = 1
VARIANTS = ("shot", "pasted", "walk", "approach")
WALKS = ("walk", "approach")  # the variants pasted along a walk through one room
N_REFERENCE_PHOTOS = 3
N_OTHER_FRAMES = 4
N_EMPTY_FRAMES = 3

# PIN's camera: 360 px wide, horizontal field of view 42 degrees (as the synthetic set), so a focal length of
# 180 / tan(21 deg) = 469 px; an object of longest side L metres at D metres spans 469 * L / D pixels
PASTE_OBJECT_M = 0.6  # the larger personal objects of PIN (a backpack, a bag, a teddy bear)
PASTE_DISTANCE_M = (1.0, 3.0)
APPROACH_DISTANCES_M = (3.0, 2.6, 2.2, 1.8, 1.4, 1.0)  # an approach shows each target photo at these, far to near


# ------------------------------------------------------------------ plan
@dataclass(frozen=True)
class EpisodePlan:
    episode_id: str
    split: str
    target: str
    reference_photos: tuple[str, ...]
    frames: tuple[tuple[str, str], ...]  # (kind, photo_id or room_id); kind in target, lookalike, other, empty
    distances: tuple[float | None, ...] = ()  # a walk: metres per frame (None: drawn); else empty
    room: str = ""  # a walk: the one room it is in


def reference_photos(own: Sequence[Photo], *, keep_one: bool) -> list[Photo]:
    """An instance's reference photos: those marked ``use=reference`` (up to 3), else its first ones.

    Without marked photos the first up to 3 are taken, one fewer than all when ``keep_one``
    (a target keeps a photo for its own frames).
    """
    marked = [p for p in own if p.use == REFERENCE_USE]
    if marked:
        return marked[:N_REFERENCE_PHOTOS]
    return list(own[:min(N_REFERENCE_PHOTOS, len(own) - 1 if keep_one else len(own))])


def plan_episodes(photos: Sequence[Photo], room_ids: Sequence[str], seed: int = 0,
                  split: dict[str, str] | None = None) -> list[EpisodePlan]:
    """One episode per instance with photos for its references and its frames and a same-split look-alike.

    Look-alikes are the other instances of its category. Photos marked ``use=reference`` are
    never frames, of their own episode or of another. ``split``: each instance's split
    (default ``instance_splits``).
    """
    split = split or instance_splits(photos)
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


def walk_plan(plan: EpisodePlan, room_ids: Sequence[str], instance_of: Mapping[str, str],
              seed: int = 0) -> EpisodePlan:
    """``plan`` as a walk in one room that meets each object once, in a seeded order no role decides.

    The frames group by what they show: each instance's photos (``instance_of`` a photo id) one after the other,
    the target's each at every distance of ``APPROACH_DISTANCES_M`` (the agent walks up to it), each empty view
    alone (the walk's room); the groups are then shuffled uniformly, so the target is met first, last or between
    as often as any other object.
    """
    rng = np.random.default_rng(stable_seed(seed, "walk", plan.episode_id))
    room = room_ids[int(rng.integers(len(room_ids)))]
    groups: dict[object, list[tuple[str, str, float | None]]] = {}
    for k, (kind, item) in enumerate(plan.frames):
        if kind == "empty":
            groups[("empty", k)] = [(kind, room, None)]
        elif kind == "target":
            groups.setdefault(instance_of[item], []).extend((kind, item, d) for d in APPROACH_DISTANCES_M)
        else:
            groups.setdefault(instance_of[item], []).append((kind, item, None))
    keys = list(groups)
    walk = [frame for k in rng.permutation(len(keys)) for frame in groups[keys[int(k)]]]
    return replace(plan, frames=tuple((kind, item) for kind, item, _ in walk),
                   distances=tuple(d for *_, d in walk), room=room)


def approach_plan(plan: EpisodePlan, room_ids: Sequence[str], seed: int = 0) -> EpisodePlan:
    """``plan`` as a walk in one room that meets everything else first and ends at its target.

    The frames that are not the target keep their random order (empty views show the walk's
    room); then each target photo follows at every distance of ``APPROACH_DISTANCES_M``.
    """
    rng = np.random.default_rng(stable_seed(seed, "approach", plan.episode_id))
    room = room_ids[int(rng.integers(len(room_ids)))]
    met = [(kind, room if kind == "empty" else item) for kind, item in plan.frames if kind != "target"]
    targets = [item for kind, item in plan.frames if kind == "target"]
    return replace(plan, frames=(*met, *(("target", t) for t in targets for _ in APPROACH_DISTANCES_M)),
                   distances=(*(None,) * len(met), *(APPROACH_DISTANCES_M * len(targets))), room=room)


# ------------------------------------------------------------------ images
def reference_views(cutouts: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Three views: one per reference photo; fewer photos are filled with their mirror images."""
    views = list(cutouts[:N_REFERENCE_PHOTOS])
    k = 0
    while len(views) < N_REFERENCE_PHOTOS:
        views.append(np.ascontiguousarray(cutouts[k % len(cutouts)][:, ::-1]))
        k += 1
    return views


def paste_into(room: np.ndarray, obj: np.ndarray, rng: np.random.Generator,
               distance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Paste an RGBA cut-out at ``distance`` metres (default: drawn) and a random position (pasted, approach).

    The distance is drawn in ``PASTE_DISTANCE_M`` unless given, and the cut-out's longer side made what
    PIN's camera shows of a ``PASTE_OBJECT_M`` object there (94-281 px): the size of the
    objects PIN asks for at the distances it is seen from, not the few dozen pixels a mug
    would take (the 128 px photos hold no detail at that size).
    """
    size = FOCAL_PX * PASTE_OBJECT_M / (float(rng.uniform(*PASTE_DISTANCE_M)) if distance is None else distance)
    h, w = obj.shape[:2]
    s = size / max(h, w)
    nw, nh = min(max(int(round(w * s)), 1), FRAME_WIDTH), min(max(int(round(h * s)), 1), FRAME_HEIGHT)
    rgba = scale_brightness(cv2.resize(obj, (nw, nh), interpolation=cv2.INTER_LINEAR), float(rng.uniform(0.85, 1.1)))
    y = int(rng.integers(0, FRAME_HEIGHT - nh + 1))
    x = int(rng.integers(0, FRAME_WIDTH - nw + 1))
    image, mask = room.copy(), np.zeros(room.shape[:2], np.uint16)
    paste(image, mask, rgba, x, y, 1)
    return image, mask


def _descriptions(instance_id: str, category: str) -> list[str]:
    name = category.replace("_", " ")
    return [f"a {name}", f"my {name} ({instance_id})", f"a real {name}, photographed in a hand"]


# ------------------------------------------------------------------ build
def build(out: str | Path, src: str | Path | None = None, *, variant: str = "shot", seed: int = 0,
          overwrite: bool = False, leave_out: Collection[str] = ()) -> FrameSet:
    """Write the look-alike frame-set of ``variant`` (``VARIANTS``) from source folder ``src``.

    Without ``src``, the source folder shipped inside the package (``PACKAGED_SRC``) is used,
    so the set builds on any install, offline. Photos whose id is in ``leave_out`` are not used
    (the frame-set's provenance lists them).
    """
    if variant not in VARIANTS:
        raise LookalikeError(f"unknown variant {variant!r}; choose one of {list(VARIANTS)}")
    src = Path(src) if src is not None else PACKAGED_SRC
    every_photo = load_photos(src)
    photos = [p for p in every_photo if p.photo_id not in leave_out]
    rooms = read_rows(src / "rooms.csv", ROOM_COLUMNS, LookalikeError)
    folder = _SourceFolder(src, {p.photo_id: p for p in photos}, {r["room_id"]: src / r["file"] for r in rooms})
    split = balanced_splits(photos) if variant in WALKS else instance_splits(photos)
    plans = plan_episodes(photos, sorted(folder.room_file), seed, split)
    if variant == "approach":
        plans = [approach_plan(p, sorted(folder.room_file), seed) for p in plans]
    if variant == "walk":
        instance_of = {p.photo_id: p.instance_id for p in photos}
        plans = [walk_plan(p, sorted(folder.room_file), instance_of, seed) for p in plans]
    # "generator" is the name frame-sets of this builder have always recorded, not a module path: moving the
    # code must not change a frame-set's bytes
    provenance = dict(generator="pin_match.lookalikes", version=LOOKALIKES_VERSION, variant=variant, seed=seed,
                      source=str(src.name), photos=len(photos), rooms=len(rooms),
                      frame_size=[FRAME_HEIGHT, FRAME_WIDTH])
    if len(photos) < len(every_photo):
        provenance["left_out"] = sorted(p.photo_id for p in every_photo if p.photo_id in leave_out)
    writer = FrameSetWriter(out, Path(out).name, overwrite=overwrite, provenance=provenance, image_ext=".png")
    with writer:
        _write_objects(writer, folder, photos, plans, split)
        for plan in plans:
            _write_episode(writer, folder, plan, variant, seed)
        return writer.close()


@dataclass(frozen=True)
class _SourceFolder:
    """What a build reads from its source folder: the photos it uses, by id, and the room photos' files, by id."""

    root: Path
    by_id: dict[str, Photo]
    room_file: dict[str, Path]

    def image_and_mask(self, photo_id: str) -> tuple[np.ndarray, np.ndarray]:
        p = self.by_id[photo_id]
        rgb = read_image(self.root / p.file)
        return rgb, read_object_mask(self.root / p.mask, rgb.shape[:2])


def _write_objects(writer: FrameSetWriter, folder: _SourceFolder, photos: Sequence[Photo],
                   plans: Sequence[EpisodePlan], split: dict[str, str]) -> None:
    """Every instance the episodes show, with its reference views cut out of its photos."""
    own_photos: dict[str, list[Photo]] = {}
    for p in sorted(photos, key=lambda p: p.photo_id):
        own_photos.setdefault(p.instance_id, []).append(p)
    used = _objects_used(plans, folder.by_id)
    for inst in sorted(used):
        ref_ids = used[inst] or tuple(p.photo_id for p in reference_photos(own_photos[inst], keep_one=False))
        cut = [cutout(*folder.image_and_mask(pid)) for pid in ref_ids]
        category = own_photos[inst][0].category
        writer.add_object(inst, category, split[inst], reference_views(cut), _descriptions(inst, category))


def _write_episode(writer: FrameSetWriter, folder: _SourceFolder, plan: EpisodePlan, variant: str,
                   seed: int) -> None:
    """One planned episode and its frames: empty room crops, photos, or their objects pasted into rooms."""
    distractors = sorted({folder.by_id[pid].instance_id for kind, pid in plan.frames if kind in ("lookalike", "other")})
    writer.add_episode(plan.episode_id, plan.split, f"lookalike_{variant}_{plan.target}", plan.target, distractors)
    roles = writer.roles(plan.episode_id)
    for step, (kind, item) in enumerate(plan.frames):
        rng = np.random.default_rng(stable_seed(seed, variant, plan.episode_id, step))
        if kind == "empty":
            image = room_crop(read_image(folder.room_file[item]), rng)
            writer.add_frame(plan.episode_id, step, image, np.zeros(image.shape[:2], np.uint16), {})
            continue
        image, frame_mask = _object_frame(*folder.image_and_mask(item), variant, plan, step, folder.room_file, rng)
        inst = folder.by_id[item].instance_id
        writer.add_frame(plan.episode_id, step, image, frame_mask, {1: (inst, roles[inst])})


def _objects_used(plans: Sequence[EpisodePlan], by_id: dict[str, Photo]) -> dict[str, tuple[str, ...]]:
    """Every instance the episodes show: targets with their reference photos, distractors with none chosen yet."""
    used: dict[str, tuple[str, ...]] = {}
    for plan in plans:
        used[plan.target] = plan.reference_photos
        for kind, pid in plan.frames:
            if kind in ("lookalike", "other"):
                used.setdefault(by_id[pid].instance_id, ())
    return used


def _object_frame(rgb: np.ndarray, mask: np.ndarray, variant: str, plan: EpisodePlan, step: int,
                  room_file: dict[str, Path], rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A photo as the frame (``shot``), or its object pasted into a room (``pasted``: a random room; a walk: the
    walk's room, at the plan's distance); with the object's mask."""
    if variant == "shot":
        return letterbox(rgb, mask, rng)
    if variant in WALKS:
        room = room_crop(read_image(room_file[plan.room]), rng)
        return paste_into(room, cutout(rgb, mask), rng, plan.distances[step])
    room = room_crop(read_image(room_file[sorted(room_file)[int(rng.integers(len(room_file)))]]), rng)
    return paste_into(room, cutout(rgb, mask), rng)


def summary(src: str | Path) -> dict[str, dict[str, int]]:
    """Photos per instance, grouped by category (what the set holds, for the docs and the report)."""
    out: dict[str, dict[str, int]] = {}
    for p in load_photos(src):
        out.setdefault(p.category, {}).setdefault(p.instance_id, 0)
        out[p.category][p.instance_id] += 1
    return out
