"""The mask check: every shipped cut-out passes it, and each rule rejects a mask made to break it."""

from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest

from pin_match.data.images import read_image
from pin_match.data.mask_check import checked_mask, mask_problems
from pin_match.data.sources.photo_folder import PACKAGED_SRC

SKIN = (205, 150, 125)  # RGB, inside the YCrCb skin box
BLUE = (30, 60, 200)


def _photo() -> tuple[np.ndarray, np.ndarray]:
    """A 128 px grey photo with a blue disk (the object) and its mask, which passes every rule."""
    img = np.full((128, 128, 3), 150, np.uint8)
    mask = np.zeros((128, 128), np.uint8)
    cv2.circle(mask, (64, 60), 30, 255, -1)
    img[mask > 0] = BLUE
    return img, mask


def test_a_clean_mask_passes():
    assert mask_problems(*_photo()) == []


@pytest.mark.parametrize("rule", ["area", "border", "pieces", "skin"])
def test_each_rule_rejects_a_mask_made_to_break_it(rule):
    img, mask = _photo()
    if rule == "area":
        mask[:] = 0
        cv2.circle(mask, (64, 60), 8, 255, -1)  # 1.2 % of the photo: a lost object
    elif rule == "border":
        mask[5:40, 5:123] = 255  # the wall along the top edge
    elif rule == "pieces":
        cv2.circle(mask, (20, 110), 8, 255, -1)  # a second piece, well above speck size
    else:
        img[88:128, 50:80] = SKIN
        mask[88:118, 50:80] = 255  # the hand below the disk, attached to it
    problems = mask_problems(img, mask)
    expected = {"area": "area", "border": "border", "pieces": "pieces", "skin": "skin-coloured"}[rule]
    assert len(problems) == 1 and expected in problems[0], problems


def test_a_hand_is_repaired_and_a_lost_object_dropped():
    img, mask = _photo()
    img[88:128, 50:80] = SKIN
    mask[88:118, 50:80] = 255
    repaired, status = checked_mask(img, mask)
    assert status.startswith("repaired") and repaired is not None
    assert not repaired[95:118, 50:80].any() and repaired[60, 64]  # the hand is gone, the disk kept
    tiny = np.zeros_like(mask)
    tiny[60:66, 60:66] = 255
    assert checked_mask(img, tiny)[0] is None


def test_every_shipped_cutout_passes_the_mask_check():
    rows = list(csv.DictReader(open(PACKAGED_SRC / "photos.csv", encoding="utf-8")))
    assert rows
    for r in rows:
        rgb = read_image(PACKAGED_SRC / r["file"])
        mask = cv2.imread(str(PACKAGED_SRC / r["mask"]), cv2.IMREAD_GRAYSCALE)
        assert mask_problems(rgb, mask) == [], r["photo_id"]
