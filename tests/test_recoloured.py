"""Recoloured twins: hue rotated under the mask only, colourful train instances only, rows naming their source."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pin_match import atomic
from pin_match.data.compose import rotate_hue
from pin_match.data.csv_rows import write_rows
from pin_match.data.sources.photo_folder import (
    OPTIONAL_PHOTO_COLUMNS,
    PHOTO_COLUMNS,
    LookalikeError,
    load_photos,
)
from pin_match.data.sources.prepare import copy_packaged_rooms
from pin_match.data.sources.twins import add_recoloured_twins


def test_rotate_hue_moves_masked_pixels_only():
    rgb = np.zeros((2, 2, 3), np.uint8)
    rgb[...] = (255, 0, 0)  # pure red: OpenCV hue 0
    mask = np.array([[True, False], [False, False]])
    out = rotate_hue(rgb, 60, mask)  # 120 degrees: green
    assert out[0, 0].tolist() == [0, 255, 0]
    assert (out[~mask] == (255, 0, 0)).all()


def source(root, rows):
    for r in rows:
        atomic.write_image(root / r["file"], np.full((32, 32, 3), r.pop("colour"), np.uint8))
        mask = np.zeros((32, 32), np.uint8)
        mask[8:24, 8:24] = 255
        atomic.write_image(root / r["mask"], mask)
    write_rows(root / "photos.csv", [*PHOTO_COLUMNS, *OPTIONAL_PHOTO_COLUMNS], rows)
    copy_packaged_rooms(root)
    atomic.write_text(root / "NOTICE.md", "# Sources and licences of these photos\n\n- cups: CC BY 4.0, x/y\n")
    return root


def row(photo, instance, colour, split="train"):
    return dict(photo_id=photo, instance_id=instance, category="cup", file=f"photos/{photo}.png",
                mask=f"masks/{photo}.png", source="github:x/y@1", source_path=f"{photo}.png", licence="CC BY 4.0",
                split=split, use="", colour=colour)


def test_twins_for_colourful_train_instances_only(tmp_path):
    src = source(tmp_path / "src", [row("red_0", "red", (200, 30, 30)), row("grey_0", "grey", (120, 120, 120)),
                                    row("blue_0", "blue", (30, 30, 200), split="val")])
    out = add_recoloured_twins(src, tmp_path / "out", hue=90)
    photos = {p.photo_id: p for p in load_photos(out)}
    assert set(photos) == {"red_0", "grey_0", "blue_0", "red_0_hue90"}  # grey has no colour, blue is val
    notice = (out / "NOTICE.md").read_text()  # the source's attribution comes along, the derived photos are named
    assert "cups: CC BY 4.0, x/y" in notice and "1 photos (`*_hue90`)" in notice
    assert (out / "rooms.csv").read_text() == (src / "rooms.csv").read_text()
    twin = photos["red_0_hue90"]
    assert (twin.instance_id, twin.category, twin.split, twin.mask) == ("red_hue90", "cup", "train", "masks/red_0.png")
    image = cv2.cvtColor(cv2.imread(str(out / twin.file)), cv2.COLOR_BGR2HSV)
    assert image[16, 16, 0] == (cv2.cvtColor(np.uint8([[[200, 30, 30]]]), cv2.COLOR_RGB2HSV)[0, 0, 0] + 90) % 180
    assert image[0, 0].tolist() == cv2.cvtColor(np.uint8([[[200, 30, 30]]]), cv2.COLOR_RGB2HSV)[0, 0].tolist()


def test_a_source_without_its_notice_is_refused_by_name(tmp_path):
    src = source(tmp_path / "src", [row("red_0", "red", (200, 30, 30))])
    (src / "NOTICE.md").unlink()
    with pytest.raises(LookalikeError, match="NOTICE.md is missing"):
        add_recoloured_twins(src, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_source_without_splits_is_refused_by_name(tmp_path):
    src = tmp_path / "src"
    rows = [row("red_0", "red", (200, 30, 30))]
    source(src, rows)
    for r in rows:
        del r["split"], r["use"]
    write_rows(src / "photos.csv", PHOTO_COLUMNS, rows)
    with pytest.raises(LookalikeError, match="photos.csv has no split column"):
        add_recoloured_twins(src, tmp_path / "out")
    assert not (tmp_path / "out").exists()
