"""Recoloured twins of a look-alike source's train instances: look-alikes that only colour tells apart.

Real same-category look-alikes mostly differ in shape and print (MyVLM's toys, figurines and
pets), so a fusion fitted on them learns to weigh colour little, and fails where look-alikes
differ by colour, which PIN's colour-heavy descriptions make common (docs/instance-matchers.md).
A twin is an instance's own photos with the object's hue rotated (pixels under its mask only),
added to the same category and split, so a fit also sees pairs that only colour separates.
Objects with little colour (mean saturation under ``min_saturation``) get no twin: rotating a
grey hue changes nothing, and an identical twin is a look-alike no signal can separate.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np

from pin_match import atomic
from pin_match.data.compose import rotate_hue
from pin_match.data.csv_rows import read_rows, write_rows
from pin_match.data.images import read_image, read_object_mask
from pin_match.data.sources import lookalike_set
from pin_match.data.sources.catalogue import SRC_REQUIRED, DataSource, register
from pin_match.data.sources.photo_folder import PHOTO_COLUMNS, ROOM_COLUMNS, LookalikeError
from pin_match.data.sources.prepare import write_source_folder


def add_recoloured_twins(src: str | Path, out: str | Path, *, hue: int = 90, min_saturation: float = 60.0,
                         split: str = "train", overwrite: bool = False) -> Path:
    """A copy of the source folder ``src`` in which every colourful instance of ``split`` has a hue-rotated twin.

    The twin ``<instance>_hue<hue>`` keeps the instance's category, split, masks, source and licence
    (its photos are derived from the instance's own, which ``source`` says); the folder's rooms
    come along and its NOTICE.md keeps the source's attributions and says what was derived.
    Written through ``prepare.write_source_folder``. Returns ``out``.
    """
    src = Path(src)
    rows = read_rows(src / "photos.csv", PHOTO_COLUMNS, LookalikeError)
    if "split" not in rows[0]:
        raise LookalikeError(f"{src / 'photos.csv'} has no split column: twins need each photo's split")
    notice_file = src / "NOTICE.md"
    if not notice_file.is_file():
        raise LookalikeError(f"{notice_file} is missing: the twins are derived from its photos, whose attribution "
                             "must come along")

    def write_photos(stage: Path) -> list[dict[str, str]]:
        for folder in ("photos", "masks"):
            shutil.copytree(src / folder, stage / folder)
        twins = []
        for instance in sorted({r["instance_id"] for r in rows if r["split"] == split}):
            photos = [r for r in rows if r["instance_id"] == instance]
            images = [(r, rgb, read_object_mask(src / r["mask"], rgb.shape[:2]) > 0)
                      for r in photos for rgb in [read_image(src / r["file"])]]
            saturation = np.concatenate([cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)[..., 1][mask] for _, rgb, mask in images])
            if saturation.mean() < min_saturation:
                continue
            for r, rgb, mask in images:
                twin = f"{r['photo_id']}_hue{hue}"
                atomic.write_image(stage / "photos" / f"{twin}.png", rotate_hue(rgb, hue, mask))
                twins.append({**r, "photo_id": twin, "instance_id": f"{instance}_hue{hue}",
                              "file": f"photos/{twin}.png",
                              "source": f"{r['source']} (hue rotated by {hue} under the mask by pin_match)"})
        return rows + twins

    def write_rooms(stage: Path) -> list[dict[str, str]]:
        room_rows = read_rows(src / "rooms.csv", ROOM_COLUMNS, LookalikeError)
        shutil.copytree(src / "rooms", stage / "rooms")
        write_rows(stage / "rooms.csv", ROOM_COLUMNS, room_rows)
        return room_rows

    def describe(all_rows: list[dict[str, str]], room_rows: list[dict[str, str]]) -> str:
        derived = len(all_rows) - len(rows)
        return (notice_file.read_text(encoding="utf-8").rstrip() + f"\n\n## Derived by pin_match\n\n{derived} photos "
                f"(`*_hue{hue}`) are the {split} photos of colourful instances with the hue rotated by {hue} under "
                "their masks; they keep their originals' licence and attribution above.\n")

    return write_source_folder(out, write_photos, describe, write_rest=write_rooms, overwrite=overwrite)


SOURCE = register(DataSource(
    name="twins",
    summary="a prepared look-alike source folder plus hue-rotated twins of its colourful train instances "
            "(prepare from a source folder that has a split column, e.g. a MyVLM or grocery one)",
    licence="that of the source folder's photos (twins are derived from them; photos.csv says so)",
    variants=lookalike_set.VARIANTS, make=lookalike_set.build, src=SRC_REQUIRED,
    prepare_inputs=("SRC",), make_source=add_recoloured_twins))
