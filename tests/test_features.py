"""The feature store: the backbone's tokens, patch labels by hand, one store per frame-set, resumed, damage named."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from pin_match.cli import main
from pin_match.contract import ConfigError
from pin_match.contract.crops import crop_boxes
from pin_match.data.writer import FrameSetWriter
from pin_match.matchers.common.patch import alpha_to_grid, patch_matcher
from pin_match.scoring.options import RunOptions
from pin_match.training.features import DamagedStoreError, FeatureStore, FeatureStoreError, build_features
from pin_match.training.frame_tokens import FRAME_TOKENS, array_path, patch_coverage

QUIET = RunOptions(progress=False)


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
    out = store.path.parents[2]
    stamps = {path: os.stat(path).st_mtime_ns for path in store.files()}
    monkeypatch.setattr("pin_match.matchers.common.backbones.TimmBackbone.encode",
                        lambda *a, **k: pytest.fail("backbone ran"))
    again = build_features(tiny_frameset, "dino", overrides=dino_cfg, out=out, run=QUIET)
    assert again.path == store.path and {path: os.stat(path).st_mtime_ns for path in again.files()} == stamps


def test_a_store_for_another_frame_set_is_refused(store, tmp_path):
    w = FrameSetWriter(tmp_path / "other", "other")
    view = np.zeros((32, 32, 4), np.uint8)
    view[8:24, 8:24] = 255
    w.add_object("o", "mug", "val", [view] * 3, ["a", "b", "c"])
    w.add_episode("e", "val", "s", "o", [])
    w.add_frame("e", 0, np.zeros((64, 64, 3), np.uint8), np.zeros((64, 64), np.uint16), {})
    other = w.close()
    with pytest.raises(FeatureStoreError, match=rf"built for frame-set .*not for .*other.*{other.fingerprint}"):
        FeatureStore.open(store.path, other)


def test_a_matcher_without_patch_features_is_refused(tiny_frameset, tmp_path):
    with pytest.raises(ConfigError, match="matcher 'color' has no patch features"):
        build_features(tiny_frameset, "color", out=tmp_path, run=QUIET)


def test_a_build_cut_off_resumes_from_its_chunks(store, tiny_frameset, dino_cfg, tmp_path, monkeypatch):
    """Killed in the second episode: that episode's chunk and the store are absent, the first episode's chunk is
    kept; the rebuild encodes only the second episode's frames and gives the uninterrupted store's arrays."""
    from pin_match.matchers.common.backbones import TimmBackbone

    real, crops = TimmBackbone.encode, []
    frames_per_episode = tiny_frameset.frames.groupby("episode_id").size()

    def dying(self, images):
        if len(images) == 2 * 2:  # a batch of 2 frames' crops (references come 3 views at a time)
            crops.append(len(images))
            if sum(crops) > 2 * frames_per_episode.iloc[0]:
                raise KeyboardInterrupt
        return real(self, images)

    monkeypatch.setattr(TimmBackbone, "encode", dying)
    run = RunOptions(batch_size=2, workers=1, progress=False)
    with pytest.raises(KeyboardInterrupt):
        build_features(tiny_frameset, "dino", overrides=dino_cfg, out=tmp_path, run=run)
    (done,) = tmp_path.rglob("chunks/*.parquet")
    assert not list(tmp_path.rglob("features_*")) and not list(tmp_path.rglob("*.tmp"))
    crops.clear()
    resumed = build_features(tiny_frameset, "dino", overrides=dino_cfg, out=tmp_path, run=run)
    assert sum(crops) == 2 * frames_per_episode.drop(done.stem).sum()  # only the episode without a chunk
    assert resumed.crops.equals(store.crops) and resumed.meta == store.meta
    for name in ("frames", "patch_object", "patch_cover", "refs", "ref_alpha"):
        np.testing.assert_array_equal(getattr(resumed, name), getattr(store, name), err_msg=name)


def test_a_split_view_opens_its_frame_sets_store_and_a_missing_store_is_named(store, tiny_frameset):
    other = tiny_frameset.split("val")
    assert FeatureStore.open(store.path, other).path == store.path  # a view of one frame-set: the same fingerprint
    with pytest.raises(FeatureStoreError, match=r"no feature store at .*features_val\.parquet: run pin-match features"):
        FeatureStore.open(store.path.with_name("features_val.parquet"))


def _copy(store, tmp_path):
    import shutil

    root = shutil.copytree(store.path.parents[2], tmp_path / "features")
    return root / store.path.relative_to(store.path.parents[2])


def test_a_damaged_store_is_named_and_rebuilt_from_its_chunks(store, tiny_frameset, dino_cfg, tmp_path, monkeypatch):
    path = _copy(store, tmp_path)
    tokens = array_path(path, FRAME_TOKENS)
    tokens.write_bytes(tokens.read_bytes()[:1000])  # a copy cut short
    with pytest.raises(DamagedStoreError, match=rf"^cannot read the feature store file {tokens} .*run pin-match "
                                                rf"features again"):
        FeatureStore.open(path)
    monkeypatch.setattr("pin_match.matchers.common.backbones.TimmBackbone.encode",
                        lambda *a, **k: pytest.fail("backbone ran"))
    healed = build_features(tiny_frameset, "dino", overrides=dino_cfg, out=tmp_path / "features", run=QUIET)
    np.testing.assert_array_equal(healed.frames, store.frames)
    path.write_bytes(b"not parquet")
    with pytest.raises(DamagedStoreError, match=rf"^cannot read the feature store {path} \(damaged"):
        FeatureStore.open(path)


def test_references_of_the_wrong_shape_are_named(store, tmp_path):
    path = _copy(store, tmp_path)
    refs = path.parent / "refs.npy"
    np.save(refs, np.zeros((2, 3, 16, 64), np.float16))
    with pytest.raises(DamagedStoreError, match=rf"references {refs} \(2, 3, 16, 64\) and .* do not fit 6 objects"):
        FeatureStore.open(path)


def test_cli_features(tiny_frameset, dino_cfg, tmp_path, capsys):
    args = ["features", str(tiny_frameset.root), "--backbone", "dino", "--out", str(tmp_path), "--quiet",
            "--split", "val", "--weights", dino_cfg["weights"], "--cfg", "model_name=test_vit", "--cfg", "img_size=64"]
    assert main(args) == 0
    line = capsys.readouterr().out
    assert line.startswith("dino@") and "4 frames (8 crops, 4x4 patches of 64 dims), 6 objects" in line
    opened = FeatureStore.open(next(Path(tmp_path).rglob("features_val.parquet")), tiny_frameset)
    assert opened.meta["split"] == "val" and len(opened.crops) == 8 and set(opened.crops.split) == {"val"}
    assert main(["features", str(tiny_frameset.root), "--backbone", "sift", "--out", str(tmp_path)]) == 2
    assert "has no patch features" in capsys.readouterr().err


def test_a_build_on_a_local_dask_cluster_is_the_local_store(store, tiny_frameset, dino_cfg, tmp_path):
    pytest.importorskip("distributed")
    args = ["features", str(tiny_frameset.root), "--backbone", "dino", "--out", str(tmp_path), "--quiet",
            "--weights", dino_cfg["weights"], "--cfg", "model_name=test_vit", "--cfg", "img_size=64",
            "--scheduler", "local", "--workers", "1"]
    assert main(args) == 0
    got = FeatureStore.open(next(tmp_path.rglob("features_all.parquet")), tiny_frameset)
    assert got.crops.equals(store.crops) and got.meta == store.meta
    # a network's float sums may differ in the last bits with a worker's threads (scoring.cluster)
    np.testing.assert_allclose(got.frames.astype(np.float32), store.frames.astype(np.float32), rtol=2e-3, atol=2e-3)
    np.testing.assert_array_equal(got.patch_object, store.patch_object)
