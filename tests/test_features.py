"""The feature store: tokens equal the backbone's, patch labels computed by hand, one store per frame-set, atomic."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from pin_match.cli import main
from pin_match.contract import ConfigError
from pin_match.contract.crops import crop_boxes
from pin_match.data.writer import FrameSetWriter
from pin_match.matchers.common.patch import alpha_to_grid, patch_matcher
from pin_match.training.features import FeatureStore, FeatureStoreError, build_features, patch_coverage


def test_tokens_are_the_backbones_on_every_crop_and_reference(store, tiny_frameset, dino_cfg):
    fs = tiny_frameset
    backbone = patch_matcher("dino", **dino_cfg).backbone
    assert store.meta["frameset_fingerprint"] == fs.fingerprint and store.grid == 4 and store.dim == 64
    assert len(store.crops) == 2 * len(fs.frames)  # PIN's two square crops per 640x360 frame
    assert store.frames.dtype == np.float16 and isinstance(store.frames, np.memmap)
    for row in store.crops.iloc[[0, 5, 13]].itertuples():
        image = fs.image(row.frame_id)
        crop = image[row.y0:row.y0 + row.height, row.x0:row.x0 + row.width]
        expected = backbone.encode([crop]).patches[0].numpy()
        np.testing.assert_allclose(store.frames[row.crop_index].astype(np.float32), expected, rtol=2e-3, atol=2e-3)
    index = store.object_index()
    views = fs.target("mug_c").views
    np.testing.assert_allclose(store.refs[index["mug_c"], 1].astype(np.float32),
                               backbone.encode([views[1][..., :3]]).patches[0].numpy(), rtol=2e-3, atol=2e-3)
    np.testing.assert_array_equal(store.ref_alpha[index["mug_c"], 2], alpha_to_grid(views[2][..., 3], 4).reshape(-1))


def test_patch_labels_by_hand(store, tiny_frameset):
    """Frame ep_train_0000 shows mug_a (a disc of diameter ~77 px centred at x 148, y 348): in the first crop
    (rows 0-360, 90-px patches) it covers only patch row 3; in the second (rows 280-640) row 0."""
    fs = tiny_frameset
    mask = fs.instance_mask("ep_train_0000") == 1
    rows = store.crops[store.crops.frame_id == "ep_train_0000"].sort_values("crop")
    boxes = crop_boxes(640, 360, "pin")
    mug_a = store.object_index()["mug_a"]
    for row, box in zip(rows.itertuples(), boxes):
        inside = mask[box.y0:box.y0 + box.height, box.x0:box.x0 + box.width]
        cover = inside.reshape(4, 90, 4, 90).mean(axis=(1, 3)).reshape(-1)  # exact: 360 = 4 x 90
        np.testing.assert_allclose(store.patch_cover[row.crop_index].astype(np.float32), cover, atol=1e-3)
        labels = store.patch_object[row.crop_index]
        assert set(labels[cover > 0]) == {mug_a} and set(labels[cover == 0]) == {-1}
    np.testing.assert_array_equal(np.nonzero(store.patch_cover[rows.crop_index.iloc[0]])[0], [13, 14])
    empty = store.crops[store.crops.frame_id == "ep_train_0003"].crop_index
    assert (store.patch_object[empty.to_numpy()] == -1).all()


def test_coverage_of_a_crop_not_divisible_by_the_grid():
    mask = np.zeros((7, 7), np.uint16)
    mask[:, :2] = 5  # 2 of 7 columns; 3 patches per side each cover 7/3 columns
    cover = patch_coverage(mask, [5], 3)[0]
    np.testing.assert_allclose(cover[:, 0], 6 / 7, atol=1e-6)     # 2 of its 7/3 columns
    np.testing.assert_allclose(cover[:, 1:], 0.0, atol=1e-6)


def test_the_store_is_reused_not_rebuilt(store, tiny_frameset, dino_cfg, monkeypatch):
    out = store.root.parents[2]
    stamp = os.stat(store.root / "frames.npy").st_mtime_ns
    monkeypatch.setattr("pin_match.matchers.common.backbones.TimmBackbone.encode",
                        lambda *a, **k: pytest.fail("backbone ran"))
    again = build_features(tiny_frameset, "dino", overrides=dino_cfg, out=out, progress=False)
    assert again.root == store.root and os.stat(again.root / "frames.npy").st_mtime_ns == stamp


def test_a_store_for_another_frame_set_is_refused(store, tmp_path):
    w = FrameSetWriter(tmp_path / "other", "other")
    view = np.zeros((32, 32, 4), np.uint8)
    view[8:24, 8:24] = 255
    w.add_object("o", "mug", "val", [view] * 3, ["a", "b", "c"])
    w.add_episode("e", "val", "s", "o", [])
    w.add_frame("e", 0, np.zeros((64, 64, 3), np.uint8), np.zeros((64, 64), np.uint16), {})
    other = w.close()
    with pytest.raises(FeatureStoreError, match=rf"built for frame-set .*not for .*other.*{other.fingerprint}"):
        FeatureStore.open(store.root, other)


def test_a_matcher_without_patch_features_is_refused(tiny_frameset, tmp_path):
    with pytest.raises(ConfigError, match="matcher 'color' has no patch features"):
        build_features(tiny_frameset, "color", out=tmp_path, progress=False)


def test_a_failed_build_leaves_nothing(tiny_frameset, dino_cfg, tmp_path, monkeypatch):
    from pin_match.matchers.common.backbones import TimmBackbone

    calls = {"n": 0}
    real = TimmBackbone.encode

    def dying(self, images):
        calls["n"] += 1
        if calls["n"] > 7:  # the probe and 6 objects passed: inside the frames
            raise KeyboardInterrupt
        return real(self, images)

    monkeypatch.setattr(TimmBackbone, "encode", dying)
    with pytest.raises(KeyboardInterrupt):
        build_features(tiny_frameset, "dino", overrides=dino_cfg, out=tmp_path, progress=False)
    assert not [p for p in tmp_path.rglob("*") if p.is_file()]


def test_cli_features(tiny_frameset, dino_cfg, tmp_path, capsys):
    args = ["features", str(tiny_frameset.root), "--backbone", "dino", "--out", str(tmp_path), "--quiet",
            "--split", "val", "--weights", dino_cfg["weights"], "--cfg", "model_name=test_vit", "--cfg", "img_size=64"]
    assert main(args) == 0
    line = capsys.readouterr().out
    assert line.startswith("dino@") and "4 frames (8 crops, 4x4 patches of 64 dims), 6 objects" in line
    meta = json.loads(next(Path(tmp_path).rglob("store.json")).read_text())
    assert meta["split"] == "val" and meta["n_crops"] == 8
    assert main(["features", str(tiny_frameset.root), "--backbone", "sift", "--out", str(tmp_path)]) == 2
    assert "has no patch features" in capsys.readouterr().err
