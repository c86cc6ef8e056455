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

import math
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from pin_match.contract import ConfigError, MatcherConfig, MatcherError, MatchResult, Target, register_matcher
from pin_match.matchers.common.patch import alpha_to_grid, patch_centres
from pin_match.matchers.effnet import EffnetConfig, EffnetMatcher

AGGREGATES = ("topk", "mutual")


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


def reference_cells(alpha_grid: torch.Tensor, min_alpha: float) -> torch.Tensor:
    """Indices of the cells covered by the mask at ``min_alpha``; the most covered cell when none is.

    A small object can cover no cell well at a coarse stride; its best-covered cell still
    describes it better than nothing, and a view is never left without parts.
    """
    flat = alpha_grid.reshape(-1)
    keep = torch.nonzero(flat >= min_alpha).reshape(-1)
    return keep if len(keep) else flat.argmax().reshape(1)


def view_score(best: torch.Tensor, mutual: torch.Tensor, aggregate: str, top_fraction: float) -> float:
    """One view's score from its reference cells' best-match cosines (and which of them are mutual)."""
    if aggregate == "topk":
        k = max(1, math.ceil(top_fraction * len(best)))
        return float(best.topk(k).values.mean())
    return float((best * mutual).sum() / len(best))


def part_matches(refs: torch.Tensor, views: torch.Tensor, cells: torch.Tensor, aggregate: str,
                 top_fraction: float) -> tuple[float, np.ndarray, np.ndarray]:
    """One crop: (score, indices of the chosen frame cells, their best cosine).

    ``refs`` (R, D) are the reference cells, ``views`` (R,) the view each belongs to,
    ``cells`` (N, D) the crop's cells.
    """
    sims = F.normalize(refs, dim=-1) @ F.normalize(cells, dim=-1).T  # (R, N)
    best, choice = sims.max(dim=1)
    scores = []
    for v in torch.unique(views):
        rows = torch.nonzero(views == v).reshape(-1)
        back = sims[rows].argmax(dim=0)  # per frame cell, its best reference cell of this view
        mutual = (back[choice[rows]] == torch.arange(len(rows))).to(best.dtype)
        scores.append(view_score(best[rows], mutual, aggregate, top_fraction))
    chosen = torch.unique(choice)
    chosen_scores = torch.full((cells.shape[0],), -math.inf).scatter_reduce(0, choice, best, reduce="amax")[chosen]
    return max(scores), chosen.numpy(), chosen_scores.numpy().astype(np.float32)


@register_matcher("effnet-parts")
class EffnetPartsMatcher(EffnetMatcher):
    """EfficientNet-Lite0 cells as parts: reference cells matched one by one to crop cells (see module doc)."""

    Config = PartsConfig
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
