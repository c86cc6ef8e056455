"""Torch building blocks shared by matchers and training: the prototype rule and the trained head's inference half."""

from pin_match.nn.head import (
    HeadBackbone,
    HeadError,
    ProjectionHead,
    load_head,
    prototypes,
    read_head_config,
    save_head,
)
from pin_match.nn.prototypes import masked_mean, patch_scores

__all__ = ["HeadBackbone", "HeadError", "ProjectionHead", "load_head", "masked_mean", "patch_scores",
           "prototypes", "read_head_config", "save_head"]
