"""``effnet-parts``: every reference patch looks for its own best frame patch, instead of one averaged prototype.

A mask-averaged prototype keeps what a category shares (the mean of its parts) and loses
where the parts differ, which is what tells two instances of one category apart. Here each
reference cell inside the alpha mask keeps its own vector; in a crop, each finds its best
cell by cosine, and a view's score aggregates those best matches:

- ``aggregate=topk``: the mean of the best ``top_fraction`` of the view's reference cells'
  best-match cosines (a view is only partly visible, so the worst-matched cells are left out);
- ``aggregate=mutual``: the sum of the best-match cosines of the cells whose match is mutual
  (the frame cell's best reference cell of that view is the cell itself), over the number of
  the view's cells: the fraction of the view's parts found, weighted by how well.

The crop's score is the max over views (one frame sees the object from one side). Points are
the frame cells chosen as best match by some reference cell, each with the best cosine that
chose it; every view score is at most that cosine, so a frame matched at sigma always has a point.
The backbone is ``effnet``'s (same weights, ``layer`` and ``img_size`` settings); the defaults
are its ``head`` at 448 px, which keeps instance detail far better than ``blocks.3`` at 224
on real look-alikes (docs/instance-matchers.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from pin_match.contract import ConfigError, MatcherConfig, MatcherError, MatchResult, Target, register_matcher
from pin_match.matchers.common.cell_parts import AGGREGATES, part_matches, reference_cells
from pin_match.matchers.common.efficientnet import LITE0_WEIGHTS, EfficientNetMatcher, EffnetConfig
from pin_match.matchers.common.patch import alpha_to_grid, patch_centres


@dataclass
class PartsConfig(EffnetConfig):
    """``effnet``'s backbone settings (other defaults) plus how the reference cells' best matches are aggregated."""

    layer: str = "head"
    img_size: int = 448
    aggregate: str = field(default="topk", metadata={"help": "topk (mean of the best top_fraction of a view's "
                                                             "cells' best matches) or mutual (mutual matches, "
                                                             "weighted by cosine, over the view's cells)"})
    top_fraction: float = field(default=0.25, metadata={"help": "topk: share of a view's reference cells kept"})
    min_alpha: float = field(default=0.5, metadata={"help": "a reference cell is a part when its mask cover "
                                                            "(alpha resized to the grid) reaches this"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.aggregate not in AGGREGATES:
            raise ConfigError(f"{type(self).__name__}: aggregate={self.aggregate!r}; choose one of "
                              f"{', '.join(AGGREGATES)}")
        if not 0.0 < self.top_fraction <= 1.0:
            raise ConfigError(f"{type(self).__name__}: top_fraction={self.top_fraction} must be in (0, 1]")
        if not 0.0 < self.min_alpha <= 1.0:
            raise ConfigError(f"{type(self).__name__}: min_alpha={self.min_alpha} must be in (0, 1]")


@register_matcher("effnet-parts")
class EffnetPartsMatcher(EfficientNetMatcher):
    """EfficientNet-Lite0 cells as parts: reference cells matched one by one to crop cells (see module doc)."""

    Config = PartsConfig
    weights_spec = LITE0_WEIGHTS  # effnet's
    version = 1
    # the best mean F1 on the real look-alike set's train instances, both variants (docs/instance-matchers.md)
    default_sigma = 0.34
    paper = ("part matching of CNN cells (cf. Zhang et al., Personalize Segment Anything, ICLR 2024, "
             "which matches target features location by location) on EfficientNet-Lite0 (Tan & Le, ICML 2019)")

    def __init__(self, cfg: MatcherConfig | None = None, **kwargs) -> None:
        super().__init__(cfg, **kwargs)
        self._views: torch.Tensor | None = None  # per reference cell, the view it came from

    def _target_vectors(self, target: Target) -> torch.Tensor:
        backbone = self.backbone
        feats = backbone.encode([v[..., :3] for v in target.views]).patches
        refs, views = [], []
        for i, view in enumerate(target.views):
            keep = reference_cells(alpha_to_grid(view[..., 3], backbone.grid), self.cfg.min_alpha)
            refs.append(feats[i, keep])
            views.append(torch.full((len(keep),), i))
        self._views = torch.cat(views)
        return torch.cat(refs)

    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        backbone = self.backbone
        feats = backbone.encode(crops).patches
        refs, grid = self.targets, backbone.grid
        views = self._views
        if views is None or len(views) != len(refs):
            raise MatcherError(f"matcher {self.display_name}: call prepare(target) first")
        results = []
        for crop, cells in zip(crops, feats):
            score, chosen, chosen_scores = part_matches(refs, views, cells, self.cfg.aggregate,
                                                        self.cfg.top_fraction)
            centres = patch_centres(grid, crop.shape[1], crop.shape[0])
            results.append(MatchResult(score=score, points=centres[chosen], point_scores=chosen_scores))
        return results
