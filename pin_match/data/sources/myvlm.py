"""A development look-alike source of real instances at full resolution: the MyVLM concept photos.

MyVLM (Alaluf et al., ECCV 2024; github woonsango/MyVLM) ships ``dataset/data_concept_embedding/
<concept>/``: 7-17 in-the-wild photos of each of 31 personal objects and pets, 452 to 4000 px, the
object anywhere in the scene. Several concepts share a kind, so they are each other's real
look-alikes: three dogs, two cats, two cups, three sheep soft toys, ten toy figures and eight
figurines (``CONCEPT_CATEGORIES``). The three concepts with no other of their kind (a bean-bag
chicken, a teapot, running shoes) are left out.

``prepare_myvlm`` turns a checkout into the source folder ``pin_match.data.sources.lookalike_set.build``
reads (docs/lookalike-set.md):

- a concept is an instance; its photos are used as listed in ``myvlm_boxes.csv`` (shipped with
  pin_match: our own annotation, not MyVLM's): a box drawn by eye around the object, or the
  reason the photo is left out (a second dog or toy touching it, a composited backdrop, a
  different plush), every photo having been looked at on a contact sheet;
- the photo is cropped to its box grown by ``PAD`` per side (so a person beside a dog, or a
  small cup in a kitchen, stays out of the frame) and shrunk to at most ``MAX_SIDE`` px: the
  frames are 640x360, so more pixels would only slow the build;
- its mask is GrabCut started from the box (``box_mask``); a photo whose mask fails
  ``pin_match.data.mask_check`` is left out, and NOTICE.md lists it with why. The hand rule is
  not applied: no kept photo shows a hand, and the skin box takes tan dogs and pink toys;
- splits by instance with the grocery rule (``pin_match.data.sources.photo_folder.category_splits``): the toy
  figures are halved, the smaller categories go whole to one split so each keeps its look-alikes;
- empty rooms: the TUM office photos shipped with pin_match.

Licence: Snap Inc.'s non-commercial, academic-purposes licence (the repository's LICENSE; its
README puts the dataset under it). The photos are downloaded by the user, never shipped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pin_match.data.compose import largest_piece
from pin_match.data.csv_rows import read_rows
from pin_match.data.images import read_image
from pin_match.data.mask_check import mask_problems
from pin_match.data.sources import lookalike_set
from pin_match.data.sources.catalogue import SRC_REQUIRED, DataSource, register
from pin_match.data.sources.photo_folder import LookalikeError, category_splits
from pin_match.data.sources.prepare import Checkout, add_photo, notice, open_checkout, write_source_folder

MYVLM_SOURCE = "github:woonsango/MyVLM"
CONCEPT_FOLDER = Path("dataset", "data_concept_embedding")
BOXES_CSV = Path(__file__).resolve().with_name("myvlm_boxes.csv")
BOX_COLUMNS = ("concept", "file", "x0", "y0", "x1", "y1", "dropped")
MYVLM_LICENCE = "Snap Inc. non-commercial, academic purposes only (MyVLM, Alaluf et al. 2024; file LICENSE)"
# bo and mam are the Yo'LLaVA pets (Nguyen et al., NeurIPS 2024), which MyVLM redistributes under its licence
YOLLAVA_CONCEPTS = ("bo", "mam")
YOLLAVA_LICENCE = f"{MYVLM_LICENCE}; photo from the Yo'LLaVA dataset (Nguyen et al. 2024)"
CONCEPT_CATEGORIES = {
    "billy_dog": "dog", "maeve_dog": "dog", "bo": "dog",
    "my_cat": "cat", "mam": "cat",
    "espresso_cup": "cup", "skulls_mug": "cup",
    "sheep_plush": "sheep_soft_toy", "sheep_pillow": "sheep_soft_toy", "sheep_toy": "sheep_soft_toy",
    "asian_doll": "toy_figure", "boy_funko_pop": "toy_figure", "iverson_funko_pop": "toy_figure",
    "green_doll": "toy_figure", "minion_toy": "toy_figure", "robot_toy": "toy_figure",
    "gengar_toy": "toy_figure", "rabbit_toy": "toy_figure", "dangling_child": "toy_figure",
    "small_penguin": "toy_figure",
    "bull": "figurine", "cat_statue": "figurine", "ceramic_head": "figurine", "elephant_statue": "figurine",
    "elephant_sphere": "figurine", "gold_pineapple": "figurine", "red_chicken": "figurine",
    "red_piggy_bank": "figurine",
}
PAD = 0.25  # of the box's width (height) added left and right (above and below) before cropping
MAX_SIDE = 640  # the frame's height: a larger crop is never shown at full size
GRABCUT_SIDE = 320
GRABCUT_ITERATIONS = 5


@dataclass(frozen=True)
class BoxedPhoto:
    concept: str
    file: str  # the file name inside the concept's folder
    box: tuple[int, int, int, int] | None  # x0, y0, x1, y1 in the photo's pixels; None = left out
    dropped: str  # why it is left out by eye ("" when boxed)

    @property
    def instance_id(self) -> str:
        return f"myvlm_{self.concept}"

    @property
    def category(self) -> str:
        return CONCEPT_CATEGORIES[self.concept]

    @property
    def photo_id(self) -> str:
        return f"myvlm_{self.concept}_{Path(self.file).stem.rsplit('_', 1)[-1]}"


def read_boxes(path: str | Path = BOXES_CSV) -> list[BoxedPhoto]:
    """The annotated photos: a box, or the reason the photo is left out, never both."""
    path = Path(path)
    out = []
    for r in read_rows(path, BOX_COLUMNS, LookalikeError):
        if r["concept"] not in CONCEPT_CATEGORIES:
            raise LookalikeError(f"{path}: unknown concept {r['concept']!r} (known: {sorted(CONCEPT_CATEGORIES)})")
        coords = [r[c].strip() for c in BOX_COLUMNS[2:6]]
        if bool(r["dropped"].strip()) == all(coords) or (not all(coords) and any(coords)):
            raise LookalikeError(f"{path}: {r['concept']}/{r['file']} needs either four box coordinates "
                                 f"or a reason in 'dropped', not both and not neither")
        box = tuple(int(c) for c in coords) if all(coords) else None
        if box is not None and (box[2] <= box[0] or box[3] <= box[1] or min(box) < 0):
            raise LookalikeError(f"{path}: {r['concept']}/{r['file']} has an empty or negative box {box}")
        out.append(BoxedPhoto(r["concept"], r["file"], box, r["dropped"].strip()))
    return out


def crop_to_box(rgb: np.ndarray, box: tuple[int, int, int, int]) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """The photo cropped to ``box`` grown by ``PAD`` and shrunk to ``MAX_SIDE``, with the box in the crop's pixels."""
    h, w = rgb.shape[:2]
    x0, y0, x1, y1 = min(box[0], w - 1), min(box[1], h - 1), min(box[2], w), min(box[3], h)
    px, py = int(PAD * (x1 - x0)), int(PAD * (y1 - y0))
    cx0, cy0, cx1, cy1 = max(x0 - px, 0), max(y0 - py, 0), min(x1 + px, w), min(y1 + py, h)
    crop = rgb[cy0:cy1, cx0:cx1]
    s = min(1.0, MAX_SIDE / max(crop.shape[:2]))
    if s < 1.0:
        crop = cv2.resize(crop, (max(round(crop.shape[1] * s), 1), max(round(crop.shape[0] * s), 1)),
                          interpolation=cv2.INTER_AREA)
    inner = tuple(int(round(v * s)) for v in (x0 - cx0, y0 - cy0, x1 - cx0, y1 - cy0))
    return np.ascontiguousarray(crop), inner


def box_mask(rgb: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """The object inside ``box`` (uint8, 255 = object): GrabCut from the box, its largest piece, holes filled.

    Outside the box is sure background; the box holds the object and what lies behind it.
    GrabCut runs on a copy shrunk to ``GRABCUT_SIDE`` (its cost grows with the pixels; on two
    shared cores a full-size crop takes seconds) and its mask is scaled back up. A box over the
    whole photo leaves GrabCut no background to learn from: the object fills the photo, and so
    does its mask (which the mask check then rejects). Deterministic (OpenCV's RNG seeded). All
    zero when GrabCut keeps nothing.
    """
    h, w = rgb.shape[:2]
    if box[0] <= 0 and box[1] <= 0 and box[2] >= w and box[3] >= h:
        return np.full((h, w), 255, np.uint8)
    s = min(1.0, GRABCUT_SIDE / max(h, w))
    small = cv2.resize(rgb, (max(round(w * s), 1), max(round(h * s), 1)), interpolation=cv2.INTER_AREA)
    x0, y0, x1, y1 = (int(round(v * s)) for v in box)
    seed = np.zeros(small.shape[:2], np.uint8)
    cv2.setRNGSeed(0)
    cv2.grabCut(np.ascontiguousarray(small[..., ::-1]), seed, (x0, y0, max(x1 - x0, 1), max(y1 - y0, 1)),
                np.zeros((1, 65)), np.zeros((1, 65)), GRABCUT_ITERATIONS, cv2.GC_INIT_WITH_RECT)
    fg = np.where(np.isin(seed, (cv2.GC_FGD, cv2.GC_PR_FGD)), 255, 0).astype(np.uint8)
    fg = (cv2.resize(fg, (w, h), interpolation=cv2.INTER_LINEAR) > 127).astype(np.uint8)
    fg = largest_piece(cv2.morphologyEx(fg, cv2.MORPH_OPEN, np.ones((5, 5), np.uint8)))
    if not fg.any():
        return fg
    holes = cv2.floodFill(fg.copy() * 255, np.zeros((h + 2, w + 2), np.uint8), (0, 0), 255)[1] == 0
    return np.where((fg > 0) | holes, 255, 0).astype(np.uint8)


def prepare_myvlm(myvlm_repo: str | Path, out: str | Path, *, boxes: str | Path = BOXES_CSV,
                  overwrite: bool = False) -> Path:
    """Write a look-alike source folder from a checkout of woonsango/MyVLM and the boxes of ``boxes``."""
    checkout = open_checkout(myvlm_repo, MYVLM_SOURCE, CONCEPT_FOLDER, "MyVLM",
                             "Snap's licence must travel with the photos")
    photos = read_boxes(boxes)
    folder = checkout.root / CONCEPT_FOLDER
    missing = [f"{p.concept}/{p.file}" for p in photos if p.box and not (folder / p.concept / p.file).is_file()]
    if missing:
        raise LookalikeError(f"{folder} lacks photos boxed in {boxes}: {missing}")
    split = category_splits(list({p.concept: p for p in photos if p.box}.values()))  # one entry per concept
    left_out = [(p, p.dropped) for p in photos if not p.box]

    def write_photos(stage: Path) -> list[dict[str, str]]:
        rows = []
        for p in photos:
            if p.box:
                row, why = _photo_row(checkout, stage, p, split[p.instance_id])
                if row:
                    rows.append(row)
                else:
                    left_out.append((p, why))
        return rows

    return write_source_folder(out, write_photos, lambda rows, rooms: _notice(checkout, rows, left_out, rooms),
                               overwrite=overwrite)


def _photo_row(checkout: Checkout, stage: Path, p: BoxedPhoto, split: str) -> tuple[dict | None, str]:
    """Crop, mask and write one photo: its photos.csv row, or None and why its mask fails the check."""
    source_path = (CONCEPT_FOLDER / p.concept / p.file).as_posix()
    crop, box = crop_to_box(read_image(checkout.root / source_path), p.box)
    kept = box_mask(crop, box)
    problems = mask_problems(crop, kept, hand=False)
    if problems:
        return None, "mask check: " + "; ".join(problems)
    file, mask_file = add_photo(stage, p.photo_id, crop, ".jpg", kept)
    return dict(photo_id=p.photo_id, instance_id=p.instance_id, category=p.category, file=file, mask=mask_file,
                source=checkout.source, source_path=source_path,
                licence=YOLLAVA_LICENCE if p.concept in YOLLAVA_CONCEPTS else MYVLM_LICENCE,
                split=split, use=""), ""


def _notice(checkout: Checkout, rows: list[dict], left_out: list[tuple[BoxedPhoto, str]],
            room_rows: list[dict]) -> str:
    dropped = "\n".join(f"  - `{p.concept}/{p.file}`: {why}" for p, why in sorted(left_out, key=lambda t: t[0].file))
    photos = f"""`photos/` ({len(rows)} photos of {len({r['instance_id'] for r in rows})} concepts) and their masks
  (`masks/`, by `pin_match.data.sources.myvlm.box_mask` from the boxes in
  `pin_match/data/sources/myvlm_boxes.csv`): **MyVLM** concept photos, Y. Alaluf, E. Richardson,
  S. Tulyakov, K. Aberman and D. Cohen-Or, "MyVLM: Personalizing VLMs for User-Specific Queries",
  ECCV 2024, https://github.com/woonsango/MyVLM, commit {checkout.commit or 'unknown (not a git checkout)'},
  folder `{CONCEPT_FOLDER.as_posix()}/`. The concepts `{'` and `'.join(YOLLAVA_CONCEPTS)}` are pets from the
  Yo'LLaVA dataset (T. Nguyen et al., NeurIPS 2024), as MyVLM redistributes them.
  Licence: **Snap Inc.'s licence for non-commercial, academic purposes only**, copied below; do not
  redistribute these files for any other purpose. Each photo's licence and path are in `photos.csv`.
  Changes: cropped around the object, shrunk to at most {MAX_SIDE} px, re-encoded as JPEG, renamed,
  masks added.
- Photos left out ({len(left_out)}):
{dropped}"""
    return notice(photos, room_rows, "MyVLM", checkout.licence_text)


SOURCE = register(DataSource(
    name="myvlm",
    summary="real look-alikes from a MyVLM checkout: pets, toys and figurines, several per category, boxed by "
            "eye (prepare first; never shipped)",
    licence=MYVLM_LICENCE,
    variants=lookalike_set.VARIANTS, make=lookalike_set.build, src=SRC_REQUIRED,
    prepare_inputs=("MYVLM_REPO",), make_source=prepare_myvlm))
