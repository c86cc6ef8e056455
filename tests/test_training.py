"""pin-match train and the learned matcher on the tiny hand-made frame-set with a tiny random ViT.

What is checked: the bad inputs are named, an untrained head is exactly the frozen matcher,
training lowers its loss, a run stopped after epoch k and resumed equals an uninterrupted
one to the bit, the checkpoint carries its provenance, and the head scores through the
ordinary pipeline (the matcher agrees with the store-based scores, its id follows the
checkpoint's content).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

import pin_match
from pin_match import create_matcher
from pin_match.cli import main
from pin_match.contract.testing import contract_target
from pin_match.contract.weights import WeightsError
from pin_match.data.writer import FrameSetWriter
from pin_match.matchers.common.patch import alpha_to_grid
from pin_match.nn.head import ProjectionHead, load_head
from pin_match.scoring import RunOptions, score
from pin_match.training import Backbone, TrainConfig, TrainingError, store_frame_scores, train

FAST = dict(hidden=16, batch_crops=4, patience=100, threads=1)


@pytest.fixture(scope="module")
def head_dir(tiny_frameset, store, dino_cfg, tmp_path_factory):
    out = tmp_path_factory.mktemp("heads") / "tiny"
    train(tiny_frameset, out, backbone=Backbone("dino", dino_cfg), features=store, cfg=TrainConfig(epochs=3, **FAST),
          progress=False)
    return out


def _one_episode_frameset(root, split: str, same_category: bool):
    w = FrameSetWriter(root, root.name)
    view = np.zeros((48, 48, 4), np.uint8)
    view[8:40, 8:40] = (200, 40, 40, 255)
    w.add_object("mug_a", "mug", split, [view] * 3, ["a red mug", "the mug", "red cup"])
    w.add_object("mug_b", "mug" if same_category else "ball", split, [view] * 3, ["x", "y", "z"])
    w.add_episode("e0", split, "s", "mug_a", ["mug_b"])
    roles = w.roles("e0")
    image, mask = np.zeros((64, 64, 3), np.uint8), np.zeros((64, 64), np.uint16)
    mask[10:20, 10:20] = 1
    w.add_frame("e0", 0, image, mask, {1: ("mug_b", roles["mug_b"])})
    return w.close()


def test_a_frame_set_without_a_train_split_is_refused(tmp_path, capsys):
    fs = _one_episode_frameset(tmp_path / "valonly", "val", same_category=True)
    with pytest.raises(TrainingError, match=r"has no train split \(its episodes are in \['val'\]\)"):
        train(fs, tmp_path / "head", backbone=Backbone("dino"))
    assert main(["train", str(fs.root), "--out", str(tmp_path / "h"), "--backbone", "dino"]) == 2
    assert "no train split" in capsys.readouterr().err


def test_a_train_split_without_look_alikes_is_refused(tmp_path):
    fs = _one_episode_frameset(tmp_path / "nosame", "train", same_category=False)
    with pytest.raises(TrainingError, match="shows no same-category distractor in any frame"):
        train(fs, tmp_path / "head", backbone=Backbone("dino"))


def test_a_backbone_without_patch_features_is_refused(tiny_frameset, tmp_path):
    with pytest.raises(pin_match.errors.PinMatchError, match="matcher 'sift' has no patch features"):
        train(tiny_frameset, tmp_path / "head", backbone=Backbone("sift"), features=tmp_path)


def test_a_store_of_another_frame_set_is_refused(store, tmp_path):
    other = _one_episode_frameset(tmp_path / "other", "train", same_category=True)
    with pytest.raises(TrainingError, match="was built for frame-set"):
        train(other, tmp_path / "head", backbone=Backbone("dino"), features=store)


def test_an_untrained_head_is_the_frozen_matcher(store, tiny_frameset):
    torch.manual_seed(3)
    head = ProjectionHead(store.dim, 16)
    x = torch.randn(5, store.dim)
    assert torch.equal(head(x), x)
    frozen = store_frame_scores(store, tiny_frameset, None, "val")
    np.testing.assert_array_equal(store_frame_scores(store, tiny_frameset, head, "val").score, frozen.score)


def test_checkpoint_provenance_and_learning(head_dir, store, tiny_frameset):
    config = json.loads((head_dir / "config.json").read_text())
    assert config["frameset_fingerprint"] == tiny_frameset.fingerprint
    assert config["backbone"] == "dino" and config["backbone_id"] == store.backbone_id
    assert config["seed"] == 0 and config["pin_match_version"] == pin_match.__version__ and config["finished"]
    assert len(config["holdout_objects"]) == 1  # one of the two train mugs (the queries) is held out
    assert sorted(config["fit_objects"] + config["holdout_objects"]) == ["mug_a", "mug_b"]
    losses = [h["loss"] for h in config["history"][1:]]
    assert [h["epoch"] for h in config["history"]] == [0, 1, 2, 3] and losses[-1] < losses[0]
    assert np.isfinite(config["sigma"])
    state = load_file(str(head_dir / "state.safetensors"))
    assert state["head.fc2.weight"].abs().sum() > 0  # the residual branch left zero: it learned something


def test_a_resumed_run_equals_an_uninterrupted_one(tiny_frameset, store, dino_cfg, tmp_path):
    cfg = TrainConfig(epochs=4, **FAST)
    whole = train(tiny_frameset, tmp_path / "whole", backbone=Backbone("dino", dino_cfg), features=store, cfg=cfg,
                  progress=False)
    part = train(tiny_frameset, tmp_path / "killed", backbone=Backbone("dino", dino_cfg), features=store, cfg=cfg,
                 progress=False, stop_after=2)
    assert not part["finished"] and part["epochs_run"] == 2
    resumed = train(tiny_frameset, tmp_path / "killed", backbone=Backbone("dino", dino_cfg), features=store, cfg=cfg,
                    progress=False)
    assert resumed["finished"] and resumed["epochs_run"] == whole["epochs_run"] == 4
    a, b = load_file(str(tmp_path / "whole" / "state.safetensors")), load_file(str(tmp_path / "killed" /
                                                                                   "state.safetensors"))
    assert a.keys() == b.keys() and any(k.startswith("opt.") for k in a)
    for key in a:
        assert torch.equal(a[key], b[key]), key
    assert (tmp_path / "whole" / "head.safetensors").read_bytes() == (tmp_path / "killed" /
                                                                      "head.safetensors").read_bytes()
    assert [h["loss"] for h in whole["history"]] == [h["loss"] for h in resumed["history"]]
    with pytest.raises(TrainingError, match="holds a run of another configuration"):
        train(tiny_frameset, tmp_path / "killed", backbone=Backbone("dino", dino_cfg), features=store,
              cfg=TrainConfig(epochs=5, **{**FAST, "hidden": 8}), progress=False)


def test_matcher_and_head_share_one_prototype_rule_to_float_precision(head_dir):
    """The learned matcher's target vectors are the training loss's prototypes of the same (float32) tokens."""
    from pin_match.nn import prototypes

    matcher = create_matcher("learned", weights=str(head_dir))
    target = contract_target()
    matcher.prepare(target)
    head, _ = load_head(head_dir)
    base = matcher.backbone.base
    tokens = base.encode([v[..., :3] for v in target.views]).patches.float()
    alpha = torch.stack([alpha_to_grid(v[..., 3], base.grid).reshape(-1) for v in target.views])
    with torch.inference_mode():
        expected = prototypes(head, tokens[None], alpha[None])[0]
    got = torch.nn.functional.normalize(matcher.targets.float(), dim=-1)
    torch.testing.assert_close(got, expected, atol=1e-6, rtol=1e-5)


def test_the_learned_matcher_scores_like_the_store(head_dir, store, tiny_frameset, tmp_path):
    table = score(tiny_frameset, "learned", overrides=dict(weights=str(head_dir)), split="val", out=tmp_path,
                  run=RunOptions(progress=False))
    head, config = load_head(head_dir)
    expected = store_frame_scores(store, tiny_frameset, head, "val").set_index("frame_id").score
    got = table.frames.set_index("frame_id").score
    # the store keeps tokens in float16 (the scoring path runs in float32): the two agree to float16 precision
    np.testing.assert_allclose(got[expected.index].to_numpy(), expected.to_numpy(), atol=2e-3)
    assert table.meta["default_sigma"] == pytest.approx(config["sigma"])  # the head's tuned sigma
    first_id = create_matcher("learned", weights=str(head_dir)).id
    assert first_id == table.meta["matcher_id"]
    (head_dir / "notes.txt").write_text("a changed head folder is another head")
    assert create_matcher("learned", weights=str(head_dir)).id != first_id
    (head_dir / "notes.txt").unlink()


def test_the_frozen_matcher_scores_like_the_store(store, tiny_frameset, dino_cfg, tmp_path):
    """Training's comparison scores frames by the matcher's own rule: the store's frozen scores are the matcher's."""
    table = score(tiny_frameset, "dino", overrides=dino_cfg, split="val", out=tmp_path, run=RunOptions(progress=False))
    expected = store_frame_scores(store, tiny_frameset, None, "val").set_index("frame_id").score
    got = table.frames.set_index("frame_id").score
    assert len(expected) == len(got) > 1 and expected.nunique() > 1
    # the store keeps tokens in float16 (the scoring path runs in float32): the two agree to float16 precision
    np.testing.assert_allclose(got[expected.index].to_numpy(), expected.to_numpy(), atol=2e-3)


def test_a_head_on_changed_backbone_weights_is_refused(head_dir, tmp_path):
    import shutil

    copy = tmp_path / "head"
    shutil.copytree(head_dir, copy)
    config = json.loads((copy / "config.json").read_text())
    config["backbone_id"] = "dino@000000000000"
    (copy / "config.json").write_text(json.dumps(config))
    matcher = create_matcher("learned", weights=str(copy))
    with pytest.raises(WeightsError, match="was trained on dino@000000000000.*retrain the head"):
        matcher.prepare(contract_target())
    with pytest.raises(WeightsError, match="needs weights=heads/NAME"):
        create_matcher("learned").prepare(contract_target())


def test_cli_train_then_score(tiny_frameset, store, dino_cfg, tmp_path, capsys):
    features = store.path.parents[2]
    args = ["train", str(tiny_frameset.root), "--backbone", "dino", "--weights", dino_cfg["weights"],
            "--cfg", "model_name=test_vit", "--cfg", "img_size=64", "--features", str(features),
            "--out", str(tmp_path / "head"), "--epochs", "2", "--hidden", "16", "--batch-crops", "4", "--quiet"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "held-out AUROC target vs same-category" in out and "--matcher learned" in out
    assert main(["score", str(tiny_frameset.root), "--matcher", "learned", "--weights", str(tmp_path / "head"),
                 "--out", str(tmp_path / "scores"), "--quiet"]) == 0
    assert capsys.readouterr().out.startswith("learned@")
