"""Weights that are missing or belong to another architecture are refused with the file named."""

from __future__ import annotations

import numpy as np
import pytest
import safetensors.torch

from conftest import make_view
from pin_match import Target, create_matcher
from pin_match.contract.weights import WeightsError, WeightsSpec


def _target() -> Target:
    v = make_view((200, 30, 30))
    return Target("o", "mug", (v, v, v), ("a", "b", "c"))


def test_missing_weights_file_is_named(tmp_path):
    missing = tmp_path / "nope.safetensors"
    m = create_matcher("dino", model_name="vit_tiny_patch16_224", weights=str(missing))  # construction loads nothing
    with pytest.raises(WeightsError, match=r"nope\.safetensors does not exist"):
        m.prepare(_target())
    assert not WeightsSpec("some/hub-id").available(str(missing))
    assert WeightsSpec("some/hub-id").available(str(tmp_path))


def test_weights_of_another_architecture_are_refused(tmp_path, monkeypatch):
    import timm

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    small = timm.create_model("vit_small_patch16_224", pretrained=False, num_classes=0, img_size=32)
    path = tmp_path / "vit_small.safetensors"
    safetensors.torch.save_file(small.state_dict(), path)
    m = create_matcher("dino", model_name="vit_tiny_patch16_224", img_size=32, weights=str(path))
    with pytest.raises(WeightsError, match=r"matcher dino: weights .*vit_small\.safetensors do not fit "
                                           r"vit_tiny_patch16_224 \(RuntimeError: .*state_dict"):
        m.prepare(_target())
    # the same file loads into the architecture it belongs to
    ok = create_matcher("dino", model_name="vit_small_patch16_224", img_size=32, weights=str(path))
    ok.prepare(_target())
    assert np.isfinite(ok.match(np.zeros((64, 48, 3), np.uint8)).score)


def test_changed_weights_behind_the_same_path_change_the_id(tmp_path):
    path = tmp_path / "w.safetensors"
    path.write_bytes(b"first")
    first = create_matcher("dino", weights=str(path)).id
    assert create_matcher("dino", weights=str(path)).id == first  # same content, same id
    path.write_bytes(b"second")
    assert create_matcher("dino", weights=str(path)).id != first
    moved = tmp_path / "renamed.safetensors"
    path.rename(moved)
    assert create_matcher("dino", weights=str(moved)).id == create_matcher("dino", weights=str(moved)).id
    copy = tmp_path / "copy.safetensors"
    copy.write_bytes(b"second")
    assert create_matcher("dino", weights=str(copy)).id == create_matcher("dino", weights=str(moved)).id


def test_carrier_package_missing_or_damaged_is_named(monkeypatch, tmp_path):
    spec = WeightsSpec(package="pin_match_no_such_pkg", package_file="w/model.pth", distribution="no-such-pkg")
    with pytest.raises(WeightsError, match=r"w/model.pth ship in the pip package no-such-pkg, which is not installed"):
        spec.resolve(None)
    assert not spec.available() and spec.identity(None)["version"] is None
    (tmp_path / "fake_carrier").mkdir()
    (tmp_path / "fake_carrier" / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    lacking = WeightsSpec(package="fake_carrier", package_file="w/model.pth")
    with pytest.raises(WeightsError, match=r"fake_carrier is installed but lacks w/model.pth"):
        lacking.resolve(None)
    (tmp_path / "fake_carrier" / "w").mkdir()
    (tmp_path / "fake_carrier" / "w" / "model.pth").write_bytes(b"not a torch file")
    assert lacking.resolve(None) == tmp_path / "fake_carrier" / "w" / "model.pth"
    from pin_match.contract.weights import load_torch_state
    with pytest.raises(WeightsError, match=r"cannot read the checkpoint .*model.pth \(damaged"):
        load_torch_state(lacking.resolve(None), "matcher x")


def test_one_resolver_takes_a_file_a_known_name_in_a_folder_or_the_hub(tmp_path):
    spec = WeightsSpec("no-such/repo", filename="model.safetensors")
    single = tmp_path / "any-name.bin"
    single.write_bytes(b"x")
    assert spec.resolve(str(single)) == single  # a file is taken as it is named
    folder = tmp_path / "saved"
    folder.mkdir()
    with pytest.raises(WeightsError, match=r"^matcher m: the weights folder .*saved holds no file named a\.pth or "
                                           r"model\.safetensors$"):
        spec.resolve(str(folder), "matcher m", ("a.pth",))
    (folder / "model.safetensors").write_bytes(b"y")
    assert spec.resolve(str(folder), "matcher m", ("a.pth",)) == folder / "model.safetensors"
    (folder / "a.pth").write_bytes(b"z")
    assert spec.resolve(str(folder), "matcher m", ("a.pth",)) == folder / "a.pth"  # the library's own names first
    with pytest.raises(WeightsError, match=r"^matcher m: cannot get the weights of hub id 'no-such/repo' .*pass "
                                           r"weights=<local file or folder>$"):
        spec.resolve(None, "matcher m")  # offline (conftest) and not cached


def test_a_matcher_loading_several_files_takes_a_folder_not_one_file(tmp_path, monkeypatch):
    from pin_match.contract import resolve_all

    (tmp_path / "carrier").mkdir()
    (tmp_path / "carrier" / "__init__.py").write_text("")
    for name in ("a.pth", "b.pth"):
        (tmp_path / "carrier" / name).write_bytes(name.encode())
    monkeypatch.syspath_prepend(str(tmp_path))
    specs = {"glue": WeightsSpec(package="carrier", package_file="a.pth"),
             "extractor": WeightsSpec(package="carrier", package_file="b.pth")}
    assert resolve_all(specs, None, "m") == {"glue": tmp_path / "carrier" / "a.pth",
                                             "extractor": tmp_path / "carrier" / "b.pth"}
    assert resolve_all(specs, str(tmp_path / "carrier"), "m")["extractor"] == tmp_path / "carrier" / "b.pth"
    with pytest.raises(WeightsError, match=r"^m: weights=.*a\.pth is a file; pass a folder holding a\.pth and b\.pth$"):
        resolve_all(specs, str(tmp_path / "carrier" / "a.pth"), "m")
    assert resolve_all({"glue": specs["glue"]}, str(tmp_path / "carrier" / "b.pth"), "m") == \
        {"glue": tmp_path / "carrier" / "b.pth"}  # one file for a one-file matcher
