"""The frame geometry and compositing every data source shares, and that it is written only there."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np

from pin_match.data.agent import FRAME_HEIGHT, FRAME_WIDTH
from pin_match.data.compose import (
    cutout,
    largest_piece,
    letterbox,
    paste,
    room_crop,
    scale_brightness,
    stable_seed,
)

PACKAGE = Path(__file__).resolve().parents[1] / "pin_match"
HOME = {name: "data/compose.py" for name in ("stable_seed", "cutout", "paste", "room_crop", "letterbox",
                                            "scale_brightness", "largest_piece")}
HOME |= {name: "data/agent.py" for name in ("FRAME_HEIGHT", "FRAME_WIDTH", "CAMERA_HEIGHT", "HFOV_DEG", "HALF_HFOV",
                                          "HALF_VFOV", "FOCAL_PX", "FORWARD_STEP", "TURN", "TILT", "MAX_STEPS")}


def test_every_shared_name_is_defined_in_its_one_module():
    """The frame, PIN's camera and actions (``data.agent``) and the compositing every source shares (``compose``)
    are each said once: no other module of the package defines them again."""
    for path in PACKAGE.rglob("*.py"):
        where = path.relative_to(PACKAGE).as_posix()
        tree = ast.parse(path.read_text())
        defined = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
        defined |= {t.id for n in tree.body if isinstance(n, ast.Assign) for t in ast.walk(n)
                    if isinstance(t, ast.Name) and isinstance(t.ctx, ast.Store)}
        again = sorted(name for name in defined & set(HOME) if HOME[name] != where)
        assert not again, f"{where} defines {again} again: import them from {sorted({HOME[n] for n in again})}"


def test_stable_seed_is_the_same_in_every_process():
    # fixed numbers: a seed from Python's hash() would differ from run to run
    assert stable_seed("split", "core50_o01") == 607458859
    assert stable_seed(0, "realset", "cup_red") == 1651196959


def test_cutout_crops_to_the_mask_and_clears_or_keeps_the_background():
    rgb = np.full((20, 30, 3), 200, np.uint8)
    mask = np.zeros((20, 30), np.uint8)
    mask[5:10, 8:20] = 1
    mask[5, 8] = 0  # a corner of the box outside the object
    cleared, kept = cutout(rgb, mask), cutout(rgb, mask, clear_outside=False)
    assert cleared.shape == kept.shape == (5, 12, 4)
    assert cleared[0, 0, 3] == 0 and tuple(cleared[0, 0, :3]) == (0, 0, 0)
    assert kept[0, 0, 3] == 0 and tuple(kept[0, 0, :3]) == (200, 200, 200)
    assert (cleared[1:, :, 3] == 255).all() and (cleared[1:, :, :3] == 200).all()


def test_paste_is_clipped_to_the_frame_and_marks_exactly_the_opaque_pixels():
    image = np.zeros((10, 10, 3), np.uint8)
    mask = np.zeros((10, 10), np.uint16)
    rgba = np.zeros((4, 4, 4), np.uint8)
    rgba[..., :3] = 90
    rgba[:, :2, 3] = 255
    rgba[:, 2:, 3] = 127  # under half alpha: not pasted
    paste(image, mask, rgba, 8, -2, 3)
    expected = np.zeros((10, 10), np.uint16)
    expected[0:2, 8:10] = 3
    np.testing.assert_array_equal(mask, expected)
    assert (image[mask == 3] == 90).all() and (image[mask == 0] == 0).all()
    paste(image, mask, rgba, 20, 20, 4)  # wholly outside: nothing
    assert not (mask == 4).any()


def test_room_crop_at_zoom_one_takes_the_full_height_and_one_seed_gives_one_crop():
    rows = np.repeat(np.linspace(0, 255, 480).astype(np.uint8)[:, None], 640, axis=1)
    photo = np.dstack([rows] * 3)
    a = room_crop(photo, np.random.default_rng(1))
    assert a.shape == (FRAME_HEIGHT, FRAME_WIDTH, 3)
    assert a[0, 0, 0] == 0 and a[-1, 0, 0] == 255  # top and bottom rows of the photo are both in
    np.testing.assert_array_equal(a, room_crop(photo, np.random.default_rng(1)))
    zoomed = room_crop(photo, np.random.default_rng(1), zoom=0.5)
    assert zoomed.shape == a.shape and int(zoomed[-1, 0, 0]) - int(zoomed[0, 0, 0]) < 140


def test_letterbox_keeps_the_photo_aspect_and_moves_its_mask_along():
    rgb = np.full((100, 200, 3), 255, np.uint8)
    mask = np.ones((100, 200), np.uint8)
    frame, out = letterbox(rgb, mask, np.random.default_rng(0))
    assert frame.shape == (FRAME_HEIGHT, FRAME_WIDTH, 3) and out.shape == (FRAME_HEIGHT, FRAME_WIDTH)
    assert out.sum() == FRAME_WIDTH * 180 and (frame[out == 1] == 255).all() and (frame[out == 0] != 255).all()


def test_brightness_saturates_and_keeps_alpha():
    rgba = np.array([[[100, 200, 250, 7]]], np.uint8)
    np.testing.assert_array_equal(scale_brightness(rgba, 1.2), [[[120, 240, 255, 7]]])
    np.testing.assert_array_equal(scale_brightness(rgba[..., :3], (1.0, 0.5, 0.0)), [[[100, 100, 0]]])


def test_largest_piece_keeps_the_biggest_and_returns_zeros_for_nothing():
    mask = np.zeros((10, 10), np.uint8)
    mask[0:2, 0:2] = 1
    mask[5:9, 5:9] = 1
    piece = largest_piece(mask)
    assert piece.sum() == 16 and piece[6, 6] == 1 and piece[0, 0] == 0
    assert not largest_piece(np.zeros((4, 4), np.uint8)).any()
