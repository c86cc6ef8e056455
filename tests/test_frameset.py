"""Frame-sets round-trip through the writer and loader, and every broken one is refused by name."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pandas as pd
import pytest

from pin_match.data.frameset import MANIFEST, FrameSet, FrameSetError
from pin_match.data.images import ImageFileError, read_image
from pin_match.data.writer import FrameSetWriter


def test_round_trip_tables_and_pixels(tiny_frameset):
    fs = FrameSet.load(tiny_frameset.root)
    assert list(fs.objects.columns[:3]) == ["object_id", "category", "split"]
    assert set(fs.objects.object_id) == {"mug_a", "mug_b", "ball_a", "mug_c", "mug_d", "ball_b"}
    assert fs.episodes.set_index("episode_id").loc["ep_val", "target_category"] == "mug"
    assert list(fs.frames[fs.frames.episode_id == "ep_val"].step) == [0, 1, 2, 3]
    assert set(fs.frames.split) == {"train", "val"}
    vis = fs.visibility.set_index("frame_id")
    assert vis.loc["ep_val_0000", "role"] == "target"
    assert vis.loc["ep_val_0001", "role"] == "same_category"
    assert vis.loc["ep_val_0002", "role"] == "other"
    assert "ep_val_0003" not in vis.index
    # the table agrees with the mask on disk, pixel for pixel
    mask = fs.instance_mask("ep_val_0000")
    row = vis.loc["ep_val_0000"]
    ys, xs = np.nonzero(mask == row.mask_value)
    assert row.pixels == len(xs) and (row.x0, row.y0, row.x1, row.y1) == (xs.min(), ys.min(), xs.max() + 1,
                                                                           ys.max() + 1)
    assert row.depth == pytest.approx(1.5)
    assert fs.depth("ep_val_0000")[ys[0], xs[0]] == pytest.approx(1.5)
    assert fs.image("ep_val_0000").shape == (640, 360, 3)
    assert fs.object_pixels("ep_val_0000", "mug_c").sum() == row.pixels
    target = fs.target("mug_c")
    assert target.category == "mug" and len(target.views) == 3 and target.views[0].shape[2] == 4
    assert target.descriptions[0] == "a mug number mug_c view 0"


def test_split_view_and_fingerprint(tiny_frameset):
    val = tiny_frameset.split("val")
    assert set(val.frames.episode_id) == {"ep_val"} and len(val.visibility) == 3
    assert val.fingerprint == tiny_frameset.fingerprint
    with pytest.raises(FrameSetError, match="split 'test'"):
        tiny_frameset.split("test")


@pytest.fixture
def broken(tiny_frameset, tmp_path):
    """A fresh copy of the tiny frame-set to damage."""
    root = tmp_path / "copy"
    shutil.copytree(tiny_frameset.root, root)
    return root


def _edit_json(path, fn):
    data = json.loads(path.read_text())
    fn(data)
    path.write_text(json.dumps(data))


def test_fingerprint_changes_with_content(broken, tiny_frameset):
    _edit_json(broken / "objects_descriptions.json", lambda d: d["mug_a"].__setitem__(0, "a different mug"))
    assert FrameSet.load(broken).fingerprint != tiny_frameset.fingerprint


def _set_first_cell(path, column, value):
    rows = pd.read_parquet(path)
    rows.loc[0, column] = value
    rows.to_parquet(path)


def _approach_first(root, object_id, distance, columns=("approach_of", "approach_distance")):
    """Make the first frame an approach view of ``object_id`` (None: its episode's target) at ``distance``."""
    rows = pd.read_parquet(root / "frames.parquet")
    episodes = {e["episode_id"]: e for e in json.loads((root / "episodes.json").read_text())["episodes"]}
    target = episodes[rows.episode_id[0]]["goals"][0]["object_id"]
    values = {"approach_of": object_id or target, "approach_distance": distance}
    for column in columns:
        rows[column] = pd.Series([values[column]] + [None] * (len(rows) - 1), dtype=object if column ==
                                 "approach_of" else float)
    rows.to_parquet(root / "frames.parquet")


# each damage done to a copy of the tiny frame-set, and the error that must name it
DAMAGES = {
    "missing manifest": (lambda root: (root / MANIFEST).unlink(), r"missing file .*frameset\.json"),
    "newer format version": (lambda root: _edit_json(root / MANIFEST, lambda d: d.__setitem__("version", 99)),
                             r"frameset\.json has format version 99.*upgrade pin_match"),
    "missing reference view": (lambda root: (root / "objects_images" / "mug_b" / "mug_b_1.png").unlink(),
                               r"object 'mug_b'.*holds 2 reference views, expected 3"),
    "missing reference folder": (lambda root: shutil.rmtree(root / "objects_images" / "ball_a"),
                                 r"object 'ball_a': missing reference folder"),
    "two descriptions": (lambda root: _edit_json(root / "objects_descriptions.json", lambda d: d["mug_c"].pop()),
                         r"object 'mug_c'.*holds 2 descriptions, expected 3"),
    "unknown object in episode": (
        lambda root: _edit_json(root / "episodes.json", lambda d: d["episodes"][0]["distractors"].append(
            {"object_id": "ghost", "object_category": "mug"})),
        r"episode 'ep_train' refers to unknown object id 'ghost'"),
    "unknown episode in frames": (lambda root: _set_first_cell(root / "frames.parquet", "episode_id", "ep_nowhere"),
                                  r"unknown episode id 'ep_nowhere'"),
    "unknown frame in visibility": (lambda root: _set_first_cell(root / "visibility.parquet", "frame_id", "nope_0000"),
                                    r"unknown frame id 'nope_0000'"),
    "approach view of an object not in its episode": (
        lambda root: _approach_first(root, "ball_b", 1.0),
        r"frame 'ep_train_0000' is an approach view of 'ball_b', which is not an object of its episode 'ep_train'"),
    "approach distance not finite": (lambda root: _approach_first(root, None, float("nan")),
                                     r"frame 'ep_train_0000' has approach_distance nan, not a finite distance"),
    "approach view without its distance": (lambda root: _approach_first(root, None, 1.0, ("approach_of",)),
                                           r"approach views need both columns 'approach_of' and 'approach_distance'"),
    "missing frame file": (lambda root: (root / "frames" / "ep_val" / "0002.jpg").unlink(),
                           r"frame 'ep_val_0002': missing image file .*0002\.jpg"),
}


@pytest.mark.parametrize(("damage", "message"), DAMAGES.values(), ids=DAMAGES.keys())
def test_a_damaged_frameset_is_refused_by_name(broken, damage, message):
    damage(broken)
    with pytest.raises(FrameSetError, match=message):
        FrameSet.load(broken)


def test_unknown_ids_on_access(tiny_frameset):
    with pytest.raises(FrameSetError, match="unknown frame id 'zzz'"):
        tiny_frameset.image("zzz")
    with pytest.raises(FrameSetError, match="unknown object id 'zzz'"):
        tiny_frameset.target("zzz")
    with pytest.raises(FrameSetError, match="unknown episode id 'zzz'"):
        tiny_frameset.episode("zzz")


def test_corrupt_and_truncated_images(broken):
    fs = FrameSet.load(broken)
    path = broken / "frames" / "ep_val" / "0001.jpg"
    path.write_bytes(path.read_bytes()[:50])
    with pytest.raises(ImageFileError, match=r"corrupt or unreadable image .*0001\.jpg"):
        fs.image("ep_val_0001")
    path.write_bytes(b"")
    with pytest.raises(ImageFileError, match=r"0001\.jpg"):
        fs.image("ep_val_0001")


def test_reference_without_alpha(broken):
    import cv2

    path = broken / "objects_images" / "mug_a" / "mug_a_0.png"
    rgb = read_image(path, rgba=True)[..., :3]
    cv2.imwrite(str(path), rgb)
    with pytest.raises(ImageFileError, match=r"mug_a_0\.png has no alpha channel"):
        FrameSet.load(broken).target("mug_a")


def test_writer_refuses_existing_and_leaves_nothing_on_failure(tmp_path):
    root = tmp_path / "fs"
    root.mkdir()
    with pytest.raises(FrameSetError, match="already exists"):
        FrameSetWriter(root)
    target = tmp_path / "other"
    with pytest.raises(FrameSetError, match="needs 3 views"):
        with FrameSetWriter(target) as w:
            w.add_object("x", "mug", "val", [np.zeros((4, 4, 4), np.uint8)] * 2, ["a", "b", "c"])
    assert not target.exists() and not list(tmp_path.glob(".other*"))


def test_writer_rejects_unlabelled_mask_value(tmp_path):
    with FrameSetWriter(tmp_path / "fs") as w:
        view = np.zeros((8, 8, 4), np.uint8)
        view[2:6, 2:6] = 255
        w.add_object("o", "mug", "val", [view] * 3, ["a", "b", "c"])
        w.add_episode("e", "val", "s", "o", [])
        mask = np.zeros((16, 16), np.uint16)
        mask[3, 3] = 7
        with pytest.raises(FrameSetError, match="mask value 7 has no entry in the legend"):
            w.add_frame("e", 0, np.zeros((16, 16, 3), np.uint8), mask, {1: ("o", "target")})
        w.abort()


@pytest.mark.parametrize("bad", ["shelf/mug", "..", "a\\b", ""])
@pytest.mark.parametrize("kind", ["object", "episode"])
def test_writer_refuses_an_id_that_is_not_a_folder_name(tmp_path, kind, bad):
    """An id with '/' would write nested folders that FrameSet.load never finds: refused when added."""
    view = np.zeros((8, 8, 4), np.uint8)
    view[2:6, 2:6] = 255
    with FrameSetWriter(tmp_path / "fs") as w:
        w.add_object("o", "mug", "val", [view] * 3, ["a", "b", "c"])
        with pytest.raises(FrameSetError, match=re.escape(f"{kind} id {bad!r} is not a plain name")):
            if kind == "object":
                w.add_object(bad, "mug", "val", [view] * 3, ["a", "b", "c"])
            else:
                w.add_episode(bad, "val", "s", "o", [])
        w.add_episode("e.1", "val", "s", "o", [])  # a dot inside a name is fine
        w.abort()
    assert not list(tmp_path.iterdir())
