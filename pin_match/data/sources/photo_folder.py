"""The look-alike source folder: its layout, reading and writing it, and the instance splits it implies.

A source folder (``SRC``) holds the photos, one cut-out mask per photo and where each came from:

    SRC/photos.csv   photo_id, instance_id, category, file, mask, source, source_path, licence
                     (optional: split, use)
    SRC/rooms.csv    room_id, file, source, source_path, licence
    SRC/<file>       the photos and room photos as downloaded; SRC/<mask>: 8-bit, 255 = object

The sources that download photos (``core50``, ``grocery``, ``myvlm``, ``twins``) write one through
``pin_match.data.sources.prepare``; ``pin_match.data.sources.lookalike_set.build`` turns one into a
frame-set. Two optional columns let a source fix what the build would choose: ``split`` (the
instance's split, on every photo of the source) and ``use`` (``reference``: the photo is one of
its instance's reference views and never a frame).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from pin_match.data.compose import stable_seed
from pin_match.data.csv_rows import read_rows
from pin_match.data.frameset import SPLITS
from pin_match.errors import PinMatchError

# the CORe50 photos, their masks and the TUM rooms, as core50.prepare_core50 wrote them (licences: NOTICE.md there)
PACKAGED_SRC = Path(__file__).resolve().with_name("lookalike_src")
PHOTO_COLUMNS = ("photo_id", "instance_id", "category", "file", "mask", "source", "source_path", "licence")
ROOM_COLUMNS = ("room_id", "file", "source", "source_path", "licence")
OPTIONAL_PHOTO_COLUMNS = ("split", "use")
REFERENCE_USE = "reference"
MIN_INSTANCES_TO_HALVE = 4  # halving fewer would leave an instance without a look-alike in its split


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


def load_photos(src: str | Path) -> list[Photo]:
    path = Path(src) / "photos.csv"
    photos = [Photo(r["photo_id"], r["instance_id"], r["category"], r["file"], r["mask"], r.get("split") or "",
                    r.get("use") or "") for r in read_rows(path, PHOTO_COLUMNS, LookalikeError)]
    for p in photos:
        if p.split not in ("", *SPLITS) or p.use not in ("", REFERENCE_USE):
            raise LookalikeError(f"{path}: photo {p.photo_id!r} has split {p.split!r} and use {p.use!r} "
                                 f"(split: {' or '.join(SPLITS)} or empty; use: {REFERENCE_USE!r} or empty)")
    return photos


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


def balanced_splits(photos: Sequence[Photo]) -> dict[str, str]:
    """train / val per instance, giving each split its share of the instances with two photos or more.

    Only an instance with a photo left after its references can be a target, and the hash
    rule of ``instance_splits`` can send most of them to one split (the shipped CORe50 photos:
    9 targets train, 4 val). Here a category of ``MIN_INSTANCES_TO_HALVE`` or more instances is
    dealt out alternately, most-photographed first; a smaller one goes whole to one split, so
    its instances keep their look-alikes; each category starts with the split that holds fewer
    such instances so far (categories in order of size, then name). A source that fixes splits
    keeps them (``instance_splits``).
    """
    if any(p.split for p in photos):
        return instance_splits(photos)
    by_category: dict[str, dict[str, int]] = {}
    for p in photos:
        counts = by_category.setdefault(p.category, {})
        counts[p.instance_id] = counts.get(p.instance_id, 0) + 1
    out: dict[str, str] = {}
    load = dict.fromkeys(SPLITS, 0)  # instances with two photos or more, per split
    for category in sorted(by_category, key=lambda c: (-len(by_category[c]), c)):
        counts = by_category[category]
        ranked = sorted(counts, key=lambda i: (-counts[i], stable_seed("split", i), i))
        first = min(SPLITS, key=lambda s: (load[s], s))
        order = (first, *(s for s in SPLITS if s != first))
        for k, instance in enumerate(ranked):
            out[instance] = order[k % 2] if len(ranked) >= MIN_INSTANCES_TO_HALVE else first
            load[out[instance]] += counts[instance] >= 2
    return out


def category_splits(instances: Sequence) -> dict[str, str]:
    """train / val per instance (anything with ``instance_id`` and ``category``) of a downloaded source.

    A category of ``MIN_INSTANCES_TO_HALVE`` or more instances is halved as ``instance_splits``
    halves one; a smaller category goes whole to one split, so its instances keep their
    look-alikes, the small categories alternating between train and val.
    """
    by_category: dict[str, list] = {}
    for item in instances:
        by_category.setdefault(item.category, []).append(item)
    halved = [Photo(i.instance_id, i.instance_id, i.category, "", "") for items in by_category.values()
              if len(items) >= MIN_INSTANCES_TO_HALVE for i in items]
    out = instance_splits(halved) if halved else {}
    small = sorted((c for c, items in by_category.items() if len(items) < MIN_INSTANCES_TO_HALVE),
                   key=lambda c: (-len(by_category[c]), stable_seed("split", c), c))
    for k, c in enumerate(small):
        out.update({i.instance_id: ("train", "val")[k % 2] for i in by_category[c]})
    return out
