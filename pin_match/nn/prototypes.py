"""The prototype rule and the score on it: shared by the prototype matchers and the head trained for them.

PIN's DINO / DINOv2 / CLIP baselines describe a reference view by the mean of its patch
tokens weighted by the alpha mask on the patch grid, and score a patch by its best cosine
to any of the target's views; a crop scores its best patch. A head is trained on exactly the
score the matcher computes at inference, so both call these functions.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def masked_mean(tokens: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """sum(weight x token) / sum(weight) over the patch axis: (..., P, D), (..., P) -> (..., D)."""
    w = weights.to(tokens.dtype).unsqueeze(-1)
    return (w * tokens).sum(-2) / w.sum(-2)


def patch_scores(patches: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Per patch, the max over a target's vectors of the cosine: (B, P, D), (..., T, D) -> (B, P, ...).

    ``targets`` is one target's vectors (T, D), or several targets' at once (Q, T, D), as the
    training loop scores every query object in one pass; a crop's score is the max of the
    result over its patches (axis 1). One matrix product over all vectors, so a single
    target gives the same float32 numbers whether it comes alone or among others.
    """
    sims = F.normalize(patches, dim=-1) @ F.normalize(targets, dim=-1).reshape(-1, targets.shape[-1]).T
    return sims.reshape(*sims.shape[:-1], *targets.shape[:-1]).amax(dim=-1)
