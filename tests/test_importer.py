"""A PIN recording written by the test is imported; its visibility matches the semantic frames exactly."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
from toys import write_recording

from conftest import make_view
from pin_match.data.frameset import FrameSetError
from pin_match.data.importer import import_recording


@pytest.fixture
def recording(tmp_path):
    return write_recording(tmp_path)


def test_import_matches_semantic_frames_pixel_for_pixel(recording, tmp_path):
    rec, objects, semantics = recording
    fs = import_recording(rec, objects, tmp_path / "fs", split="val")
    assert list(fs.frames.frame_id) == ["7_0000", "7_0001", "7_0002"]
    assert fs.episodes.iloc[0].target_object_id == "obj_t" and fs.episodes.iloc[0].target_category == "mug"
    for step, (sem, depth) in enumerate(semantics):
        fid = f"7_{step:04d}"
        rows = fs.visibility[fs.visibility.frame_id == fid].set_index("role")
        mask = fs.instance_mask(fid)
        for label, role in ((100000, "target"), (100001, "same_category"), (100002, "other")):
            pixels = sem == label
            if not pixels.any():
                assert role not in rows.index
                continue
            row = rows.loc[role]
            assert row.pixels == pixels.sum()
            assert np.array_equal(mask == row.mask_value, pixels)
            ys, xs = np.nonzero(pixels)
            assert (row.x0, row.y0, row.x1, row.y1) == (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)
            stored = np.round(depth[pixels] * 1000) / 1000
            assert row.depth == pytest.approx(stored.mean(), abs=1e-6)
        assert (rows.loc["target"].object_id if "target" in rows.index else "obj_t") == "obj_t"
    assert fs.target("obj_s").descriptions[1] == "obj_s description 1"


def test_import_names_the_missing_semantic_frame(recording, tmp_path):
    rec, objects, _ = recording
    (rec / "7" / "semantic" / "1.npy").unlink()
    with pytest.raises(FrameSetError, match=r"has no semantic frame .*semantic/1\.npy"):
        import_recording(rec, objects, tmp_path / "fs")
    assert not (tmp_path / "fs").exists()


def test_import_names_the_missing_object(recording, tmp_path):
    rec, objects, _ = recording
    import shutil

    shutil.rmtree(objects / "objects_images" / "obj_o")
    with pytest.raises(FrameSetError, match=r"object 'obj_o': missing reference folder"):
        import_recording(rec, objects, tmp_path / "fs")


def test_png_frames_are_kept_losslessly_by_default(recording, tmp_path):
    """Issue 14.9: the stored frame is the source file, byte for byte; JPEG only when asked."""
    rec, objects, _ = recording
    fs = import_recording(rec, objects, tmp_path / "fs")
    for step in range(3):
        fid = f"7_{step:04d}"
        stored = fs.root / fs.frames.set_index("frame_id").loc[fid, "image"]
        assert stored.suffix == ".png" and stored.read_bytes() == (rec / "7" / "rgb" / f"{step}.png").read_bytes()
        source = cv2.cvtColor(cv2.imread(str(rec / "7" / "rgb" / f"{step}.png")), cv2.COLOR_BGR2RGB)
        assert np.array_equal(fs.image(fid), source)
    assert fs.manifest["provenance"]["image_format"] == "source"
    lossy = import_recording(rec, objects, tmp_path / "jpeg", image_format="jpeg")
    error = np.abs(lossy.image("7_0000").astype(int) - fs.image("7_0000").astype(int))
    assert lossy.frames.image.str.endswith(".jpg").all() and error.max() > 0  # noise images: JPEG loses


def test_jpeg_frames_keep_their_bytes(recording, tmp_path):
    rec, objects, _ = recording
    for step in range(3):
        png = rec / "7" / "rgb" / f"{step}.png"
        cv2.imwrite(str(png.with_suffix(".jpg")), cv2.imread(str(png)), [cv2.IMWRITE_JPEG_QUALITY, 80])
        png.unlink()
    fs = import_recording(rec, objects, tmp_path / "fs")
    stored = fs.root / fs.frames.image.iloc[0]
    assert stored.suffix == ".jpg" and stored.read_bytes() == (rec / "7" / "rgb" / "0.jpg").read_bytes()


def test_views_are_taken_by_name_not_by_sorting(recording, tmp_path):
    """Issue 14.2: front/back/top named any other way would sort into a silent swap; they are refused."""
    rec, objects, _ = recording
    folder = objects / "objects_images" / "obj_o"
    for k, name in enumerate(("front", "back", "top")):
        (folder / f"obj_o_{k}.png").rename(folder / f"{name}.png")
    with pytest.raises(FrameSetError, match=r"object 'obj_o': needs exactly one obj_o_0\.png \(view 0: 0 frontal, "
                                            r"1 back, 2 top\).*'back\.png', 'front\.png', 'top\.png'"):
        import_recording(rec, objects, tmp_path / "fs")
    assert not (tmp_path / "fs").exists()


def test_views_keep_their_numbered_order(recording, tmp_path):
    rec, objects, _ = recording
    folder = objects / "objects_images" / "obj_t"
    colours = [(200, 20, 20), (20, 200, 20), (20, 20, 200)]
    for k, colour in enumerate(colours):
        cv2.imwrite(str(folder / f"obj_t_{k}.png"), cv2.cvtColor(make_view(colour), cv2.COLOR_RGBA2BGRA))
    fs = import_recording(rec, objects, tmp_path / "fs")
    views = fs.target("obj_t").views
    assert [tuple(int(c) for c in v[48, 48, :3]) for v in views] == colours


def test_objects_take_the_split_of_their_episodes(recording, tmp_path):
    """Issue 14.2: a per-episode split key; objects follow it; an object in two splits is refused."""
    rec, objects, _ = recording
    data = json.loads((rec / "episodes.json").read_text())
    data["episodes"][0]["split"] = "train"
    (rec / "episodes.json").write_text(json.dumps(data))
    fs = import_recording(rec, objects, tmp_path / "fs", split="val")
    assert set(fs.episodes.split) == {"train"} and set(fs.objects.split) == {"train"}
    second = dict(data["episodes"][0], episode_id="8", split="val")
    (rec / "8").symlink_to(rec / "7", target_is_directory=True)
    (rec / "episodes.json").write_text(json.dumps({"episodes": [data["episodes"][0], second]}))
    with pytest.raises(FrameSetError, match="object 'obj_t' is used by train and val episodes"):
        import_recording(rec, objects, tmp_path / "fs2")


def test_a_distractor_needs_descriptions_too(recording, tmp_path):
    rec, objects, _ = recording
    path = objects / "objects_descriptions.json"
    data = json.loads(path.read_text())
    del data["obj_o"]
    path.write_text(json.dumps(data))
    with pytest.raises(FrameSetError, match="object 'obj_o': no entry in .*every goal and distractor needs 3"):
        import_recording(rec, objects, tmp_path / "fs")


def with_poses(rec: Path, camera: dict) -> Path:
    """The recording's episode with PIN's geometry fields and a poses.json (every step at the start, level) holding
    ``camera``'s fields; the file's path."""
    episodes = json.loads((rec / "episodes.json").read_text())["episodes"]
    episodes[0].update(start_position=[0.0, 0.0, 0.0], start_rotation=[0.0, 0.0, 0.0, 1.0],
                       info=dict(geodesic_distance=2.0))
    episodes[0]["goals"][0]["position"] = [0.0, 0.5, -2.0]
    (rec / "episodes.json").write_text(json.dumps({"episodes": episodes}))
    path = rec / "7" / "poses.json"
    path.write_text(json.dumps({**camera, "gps_compass_pitch": [[0.0, 0.0, 0.0, 0.0]] * 3}))
    return path


def test_poses_without_the_camera_take_pins_with_a_warning_naming_the_file(recording, tmp_path):
    rec, objects, _ = recording
    path = with_poses(rec, {"hfov_deg": 60.0})
    with pytest.warns(UserWarning, match=rf"^{re.escape(str(path))} records no camera_height: PIN's camera assumed "
                                         r"\(42 degrees wide, 1\.31 m high\)"):
        fs = import_recording(rec, objects, tmp_path / "fs")
    assert fs.geometry.camera.hfov_deg == 60.0 and fs.geometry.pose("7_0000").z == pytest.approx(1.31)


def test_poses_with_the_camera_import_without_a_warning(recording, tmp_path):
    rec, objects, _ = recording
    with_poses(rec, {"hfov_deg": 60.0, "camera_height": 1.0})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fs = import_recording(rec, objects, tmp_path / "fs")
    assert not [w for w in caught if "camera assumed" in str(w.message)]
    assert fs.geometry.camera.hfov_deg == 60.0 and fs.geometry.pose("7_0000").z == pytest.approx(1.0)
