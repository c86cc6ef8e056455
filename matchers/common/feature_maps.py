"""Prototype matchers on CNN feature maps (``effnet``, ``effnet-lite1``/``-lite2``, ``mobilenetv2``): what they share.

The math is ``dino``'s (``ReferencePrototypeMatcher``: one mask-weighted prototype per
reference view, max cosine over views per feature-map cell, max over cells per crop); the
cells of one layer of a CNN play the patch tokens. The networks share one layout (seven
inverted-residual stages and a head), so they share the ``layer`` and ``img_size`` options,
the checkpoint reading, and the errors; a subclass only says how its trunk is built.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass, field

import numpy as np
import torch

from pin_match.contract import (
    ConfigError,
    CropConfig,
    misfit,
    read_state_dict,
    weights_field,
)
from pin_match.matchers.common.backbones import CNN_LAYERS, TIMM_FILES, FeatureMapBackbone
from pin_match.matchers.common.patch import ReferencePrototypeMatcher, alpha_to_grid
from pin_match.nn.prototypes import masked_mean


@dataclass
class FeatureMapConfig(CropConfig):
    """Which layer's cells are the patches, and the square input size."""

    weights: str | None = weights_field()
    layer: str = field(default="head", metadata={"help": "feature map used as patches: blocks.1 .. blocks.6 "
                                                             "(strides 4, 8, 16, 16, 32, 32) or head (1280 ch, "
                                                             "stride 32)"})
    img_size: int = field(default=448, metadata={"help": "side of the square every crop is squashed to; a "
                                                         "multiple of 32"})
    # the same scores up to float rounding, as on another device: out of the config hash, like ``device``
    compile: bool = field(default=False, metadata={
        "hash": False, "help": "torch.compile the network with static shapes: faster frames, a compilation of "
                               "some 15-40 s on the first call and on each new batch shape (docs/performance.md)"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.layer not in CNN_LAYERS:
            raise ConfigError(f"{type(self).__name__}: layer={self.layer!r}; choose one of {', '.join(CNN_LAYERS)}")
        if self.img_size < 32 or self.img_size % 32:
            raise ConfigError(f"{type(self).__name__}: img_size={self.img_size} must be a positive multiple of 32")


class FeatureMapMatcher(ReferencePrototypeMatcher):
    """Loads the carried (or the user's) checkpoint into a CNN cut at ``layer``; prototypes as ``dino``'s.

    ``weights=`` is a file, or a folder holding one of timm's file names or the carrier's.
    """

    Config = FeatureMapConfig

    @property
    @abstractmethod
    def architecture(self) -> str:
        """The network the weights must fit, as error messages name it."""

    @abstractmethod
    def _cut(self, state: dict[str, torch.Tensor], source: str) -> FeatureMapBackbone:
        """The network with ``state`` loaded, cut at the configured layer."""

    def _build_backbone(self) -> FeatureMapBackbone:
        cfg = self.cfg
        who = f"matcher {self.display_name}"
        if cfg.weights is None:
            who += f" (weights {self.weights_spec.source})"
        path = self.weights_spec.resolve(cfg.weights, who, TIMM_FILES)
        state = read_state_dict(path, who)
        try:
            backbone = self._cut(state, str(path))
        except (RuntimeError, ValueError, KeyError) as exc:
            raise misfit(who, path, self.architecture, exc) from exc
        if cfg.compile:
            # static shapes: a matcher sees few batch shapes (the reference views, a frame's crops); torch's default
            # turns dynamic at the second, and that compilation was still running after 25 min on 2 CPU cores
            backbone.trunk = torch.compile(backbone.trunk, dynamic=False)
        return backbone

    def embed_reference(self, view: np.ndarray) -> np.ndarray:
        """The view's prototype: its cells averaged under the alpha mask (all cells for an RGB image).

        A CNN's plain mean over the whole squashed view is dominated by the transparent
        background (black in RGB); the mask-weighted mean is the vector the matcher compares with.
        """
        backbone = self.backbone
        cells = backbone.encode([view[..., :3]]).patches[0]
        if view.ndim == 3 and view.shape[2] == 4 and view[..., 3].any():
            weights = alpha_to_grid(view[..., 3], backbone.grid).reshape(-1)
            return masked_mean(cells, weights).numpy().astype(np.float32)
        return cells.mean(0).numpy().astype(np.float32)
