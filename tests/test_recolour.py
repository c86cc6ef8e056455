"""The recolour source's frame-set: exact ground truth from the pastes, deterministic, loads as a frame-set."""

from __future__ import annotations

import hashlib
import sys

import numpy as np
import pytest

pytest.importorskip("skimage")

from pin_match.data.frameset import MANIFEST, FrameSet  # noqa: E402
from pin_match.data.sources import recolour, recolour_photos  # noqa: E402

SEED = 3


@pytest.fixture(scope="module")
def fs(tmp_path_factory):
    return recolour.build(tmp_path_factory.mktemp("real") / "fs", seed=SEED, targets=("patch_purple", "cup_red"))


def _digests(fs: FrameSet) -> dict[str, str]:
    files = sorted(p for p in fs.root.rglob("*") if p.is_file())
    return {str(p.relative_to(fs.root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in files}


def test_loads_with_the_layout_the_issue_asks_for(fs):
    again = FrameSet.load(fs.root)
    assert again.fingerprint == fs.fingerprint
    assert set(fs.episodes.episode_id) == {"real_patch_purple", "real_cup_red"}
    assert set(fs.frames.height) == {640} and set(fs.frames.width) == {360}
    for episode_id, target in (("real_patch_purple", "patch_purple"), ("real_cup_red", "cup_red")):
        frames = fs.frames[fs.frames.episode_id == episode_id].frame_id
        assert len(frames) == len(recolour.FRAME_KINDS)
        vis = fs.visibility[fs.visibility.frame_id.isin(frames)]
        with_target = set(vis[vis.role == "target"].frame_id)
        with_lookalike = set(vis[vis.role == "same_category"].frame_id)
        with_anything = set(vis.frame_id)
        assert len(with_target) == 5 and set(vis[vis.role == "target"].object_id) == {target}
        assert len(with_lookalike - with_target) == 3  # frames whose only same-kind object is the look-alike
        assert len(with_anything - with_target - with_lookalike) == 2  # other objects only
        assert len(set(frames) - with_anything) == 2  # nothing at all
        ref = fs.target(target)
        assert len(ref.views) == 3 and all(v.shape[2] == 4 for v in ref.views)
        assert all(set(np.unique(v[..., 3])) <= {0, 255} for v in ref.views)


def test_instance_masks_are_the_pasted_masks(fs):
    """Every frame's mask is the paste of its placements, each value the object the legend names, and the
    pixels under an object's mask show that object."""
    for episode_id in fs.episodes.episode_id:
        target = episode_id.removeprefix("real_")
        _, _, frames = recolour.episode_plan(SEED, target)
        for step, (bg, placements) in enumerate(frames):
            frame_id = f"{episode_id}_{step:04d}"
            mask = fs.instance_mask(frame_id)
            image = fs.image(frame_id).astype(np.float32)
            expected = np.zeros(mask.shape, np.uint16)
            for k, p in enumerate(placements):  # an independent paste: later placements cover earlier ones
                rgba = recolour.placed(p)
                h, w = rgba.shape[:2]
                on = np.zeros(mask.shape, bool)
                on[p.y:p.y + h, p.x:p.x + w] = rgba[:max(0, mask.shape[0] - p.y), :max(0, mask.shape[1] - p.x), 3] > 0
                expected[on] = k + 1
            np.testing.assert_array_equal(mask, expected, err_msg=frame_id)
            rows = fs.visibility[fs.visibility.frame_id == frame_id].set_index("mask_value")
            assert sorted(rows.index) == sorted(set(np.unique(expected)) - {0})
            for value, row in rows.iterrows():
                p = placements[value - 1]
                assert row.object_id == p.object_id
                assert row.pixels == int((mask == value).sum())
                rgba = recolour.placed(p)
                crop = np.zeros(mask.shape + (3,), np.float32)
                h, w = rgba.shape[:2]
                crop[p.y:p.y + h, p.x:p.x + w] = rgba[:mask.shape[0] - p.y, :mask.shape[1] - p.x, :3]
                sel = mask == value
                assert np.abs(image[sel] - crop[sel]).mean() < 6, frame_id  # JPEG q95 + sensor noise only
            background = mask == 0
            if background.any():
                assert np.abs(image[background] - bg[background]).mean() < 6, frame_id


def test_same_seed_same_bytes_other_seed_other_frames(fs, tmp_path):
    recolour_photos.cutout_rgba.cache_clear()  # GrabCut runs again: it must come out the same
    again = recolour.build(tmp_path / "again", seed=SEED, targets=("patch_purple",))
    mine, theirs = _digests(fs), _digests(again)
    shared = [k for k in theirs if k in mine and not k.startswith(("frames.parquet", "visibility", "objects.csv",
                                                                     "episodes", "objects_desc", MANIFEST))]
    assert any(k.startswith("frames/real_patch_purple/") for k in shared)
    assert any(k.startswith("objects_images/patch_purple/") for k in shared)
    assert {k: mine[k] for k in shared} == {k: theirs[k] for k in shared}
    other = recolour.build(tmp_path / "other", seed=SEED + 1, targets=("patch_purple",))
    a = fs.frames.set_index("frame_id").sha256
    b = other.frames.set_index("frame_id").sha256
    assert (a.loc[b.index] != b).mean() > 0.5


def test_missing_scikit_image_names_the_package(monkeypatch, tmp_path):
    recolour_photos.photo.cache_clear()
    recolour_photos.cutout_rgba.cache_clear()
    monkeypatch.setitem(sys.modules, "skimage", None)
    monkeypatch.setitem(sys.modules, "skimage.data", None)
    try:
        with pytest.raises(recolour_photos.RecolourSetError, match="scikit-image"):
            recolour.build(tmp_path / "x", targets=("cup_red",))
    finally:
        recolour_photos.photo.cache_clear()
        recolour_photos.cutout_rgba.cache_clear()
    assert not (tmp_path / "x").exists()


def test_unknown_target_is_refused(tmp_path):
    with pytest.raises(recolour_photos.RecolourSetError, match="no_such_thing"):
        recolour.build(tmp_path / "x", targets=("no_such_thing",))
