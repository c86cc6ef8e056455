"""The reference prototype: the one rule shared by the prototype matchers and the head trained for them.

PIN's DINO / DINOv2 / CLIP baselines describe a reference view by the mean of its patch
tokens weighted by the alpha mask on the patch grid. A head is trained on exactly the
score the matcher computes at inference, so both call this function.
"""

from __future__ import annotations

import torch


def masked_mean(tokens: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """sum(weight x token) / sum(weight) over the patch axis: (..., P, D), (..., P) -> (..., D)."""
    w = weights.to(tokens.dtype).unsqueeze(-1)
    return (w * tokens).sum(-2) / w.sum(-2)
