"""The look-alike source folder: its layout, reading it, and the automatic object masks it holds.

A source folder (``SRC``) holds the photos, one automatic mask per photo and where each came from:

    SRC/photos.csv   photo_id, instance_id, category, file, mask, source, source_path, licence
                     (optional: split, use)
    SRC/rooms.csv    room_id, file, source, source_path, licence
    SRC/<file>       the photos and room photos as downloaded; SRC/<mask>: 8-bit, 255 = object

``pin_match.data.lookalikes.prepare_core50`` and ``pin_match.data.grocery.prepare_grocery`` write
one from public repositories (see docs/lookalike-set.md); ``pin_match.data.lookalikes.build``
turns one into a frame-set. Two optional columns let a source fix what the build would choose:
``split`` (the instance's split, on every photo of the source) and ``use`` (``reference``: the
photo is one of its instance's reference views and never a frame).
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pin_match import atomic
from pin_match.data.compose import largest_piece, stable_seed
from pin_match.data.frameset import SPLITS
from pin_match.data.mask_check import skin_pixels
from pin_match.errors import PinMatchError

# the CORe50 photos, their masks and the TUM rooms, as prepare_core50 wrote them (licences: NOTICE.md there)
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


def object_mask(rgb: np.ndarray, iterations: int = 5) -> np.ndarray:
    """An automatic mask (uint8, 255 = object) of the one object near the centre of a photo.

    Why this recipe: the photos centre one hand-held object, so GrabCut is seeded with the
    border as sure background and the middle as probable object; skin-coloured pixels
    (``pin_match.data.mask_check.skin_pixels``) start as probable background so the
    holding hand mostly drops out.
    The largest connected piece is kept and its holes filled. When GrabCut keeps nothing, the
    seed's middle minus skin is the mask. Deterministic (OpenCV's RNG seeded).
    """
    h, w = rgb.shape[:2]
    seed = np.full((h, w), cv2.GC_PR_BGD, np.uint8)
    by, bx = max(h // 10, 2), max(w // 10, 2)
    seed[by:h - by, bx:w - bx] = cv2.GC_PR_FGD
    seed[skin_pixels(rgb) & (seed == cv2.GC_PR_FGD)] = cv2.GC_PR_BGD
    edge = max(min(h, w) // 32, 1)
    seed[:edge], seed[-edge:], seed[:, :edge], seed[:, -edge:] = (cv2.GC_BGD,) * 4
    fallback = (seed == cv2.GC_PR_FGD).astype(np.uint8)
    cv2.setRNGSeed(0)
    cv2.grabCut(np.ascontiguousarray(rgb[..., ::-1]), seed, None, np.zeros((1, 65)), np.zeros((1, 65)),
                iterations, cv2.GC_INIT_WITH_MASK)
    fg = np.isin(seed, (cv2.GC_FGD, cv2.GC_PR_FGD)).astype(np.uint8)
    fg = largest_piece(cv2.morphologyEx(fg, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)))
    if not fg.any():
        fg = largest_piece(fallback)
    holes = cv2.floodFill(fg.copy() * 255, np.zeros((h + 2, w + 2), np.uint8), (0, 0), 255)[1] == 0
    return np.where((fg > 0) | holes, 255, 0).astype(np.uint8)


def write_csv(path: Path, columns: Sequence[str], rows: list[dict]) -> None:
    """Write ``rows`` under a header of ``columns``, atomically (a source folder is never half-written)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic.write_text(path, buf.getvalue())


def read_csv(path: Path, columns: Sequence[str]) -> list[dict]:
    if not path.is_file():
        raise LookalikeError(f"{path} is missing (a look-alike source folder needs photos.csv and rooms.csv)")
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows or any(c not in rows[0] for c in columns):
        raise LookalikeError(f"{path} needs a header with {list(columns)} and at least one row")
    return rows


def read_rgb(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise LookalikeError(f"cannot read image {path}")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray:
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if m is None or m.shape != shape:
        raise LookalikeError(f"mask {path} is missing, unreadable or not the size of its photo {shape}")
    if not (m > 127).any():
        raise LookalikeError(f"mask {path} is empty")
    return (m > 127).astype(np.uint8)


def load_photos(src: str | Path) -> list[Photo]:
    path = Path(src) / "photos.csv"
    photos = [Photo(r["photo_id"], r["instance_id"], r["category"], r["file"], r["mask"], r.get("split") or "",
                    r.get("use") or "") for r in read_csv(path, PHOTO_COLUMNS)]
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


def checkout_commit(repo: Path) -> str | None:
    """The commit a downloaded repository is at, recorded as the source of its photos (None when not a git checkout)."""
    try:
        done = subprocess.run(["git", "-C", str(repo), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 and done.stdout.strip() else None


@contextlib.contextmanager
def staged_source(out: Path, overwrite: bool) -> Iterator[Path]:
    """A hidden folder beside ``out`` to write a source folder into; it becomes ``out`` only if the block succeeds.

    A download-and-prepare step that fails half-way leaves neither a partial source nor a
    damaged earlier one behind.
    """
    if out.exists() and not overwrite:
        raise LookalikeError(f"{out} already exists: pass overwrite=True (--overwrite) to replace it")
    atomic.ensure_dir(out.parent)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        yield stage
        if out.exists():
            shutil.rmtree(out)
        os.replace(stage, out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise


def copy_packaged_rooms(stage: Path) -> list[dict[str, str]]:
    """Copy the empty rooms shipped with pin_match into a source folder being written; their rows."""
    rows = read_csv(PACKAGED_SRC / "rooms.csv", ROOM_COLUMNS)
    for r in rows:
        atomic.write_bytes(stage / r["file"], (PACKAGED_SRC / r["file"]).read_bytes())
    write_csv(stage / "rooms.csv", ROOM_COLUMNS, rows)
    return rows


def room_sources(rows: list[dict[str, str]]) -> str:
    """The rooms' licences and sources, once each, for a source folder's NOTICE."""
    return "; ".join(sorted({f"{r['licence']}, from {r['source']}" for r in rows}))
