"""Reference cells as parts: which cells of a view are its parts, and how their best matches in a crop add up.

``effnet-parts`` scores a crop this way, and ``verify``'s ``cycle`` signal is the ``mutual``
rule on a zoomed candidate; one definition keeps the signal a verifier file was fitted on the
same as the matcher it is named after.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F

AGGREGATES = ("topk", "mutual")


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
