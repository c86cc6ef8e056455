"""Batch norms folded into the convolutions that feed them, for networks that only ever run in eval mode.

In eval mode a batch norm is a per-channel scale and shift: the convolution before it can
apply both through its weights and bias, and the norm's own pass over the activations goes.
On the CPU that pass is memory-bound and cost about half as much as the convolutions of the
EfficientNet trunks (docs/performance.md). The folded network computes the same function up to
float rounding.

Which convolution feeds which norm is read from one forward pass (hooks), not from module
names, so timm's and torchvision's layouts fold alike; a norm whose input is not the output of
a convolution run once (or that convolution's output also read by another module) stays as it is.
"""

from __future__ import annotations

import torch
from torch import nn


class AfterNorm(nn.Module):
    """What is left of a norm-plus-activation module (timm's ``BatchNormAct2d``) once its norm is folded."""

    def __init__(self, drop: nn.Module, act: nn.Module) -> None:
        super().__init__()
        self.drop, self.act = drop, act

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.act(self.drop(x))


def conv_norm_pairs(model: nn.Module, example: torch.Tensor) -> list[tuple[nn.Conv2d, str, nn.BatchNorm2d]]:
    """(conv, norm name, norm) for every norm that reads a convolution's output and nothing else does."""
    names = {m: n for n, m in model.named_modules()}
    produced: dict[int, tuple[nn.Conv2d, torch.Tensor]] = {}
    calls: dict[nn.Module, int] = {}
    readers: dict[nn.Conv2d, list[nn.Module]] = {}

    def after_conv(conv: nn.Module, _inputs: tuple, out: torch.Tensor) -> None:
        calls[conv] = calls.get(conv, 0) + 1
        produced[id(out)] = (conv, out)

    def before_any(module: nn.Module, inputs: tuple) -> None:
        for x in inputs:
            hit = produced.get(id(x))
            if hit is not None and hit[1] is x:
                readers.setdefault(hit[0], []).append(module)

    leaves = [m for m in model.modules() if not list(m.children()) or isinstance(m, nn.BatchNorm2d)]
    handles = [m.register_forward_hook(after_conv) for m in model.modules() if isinstance(m, nn.Conv2d)]
    handles += [m.register_forward_pre_hook(before_any) for m in leaves]
    try:
        with torch.inference_mode():
            model(example)
    finally:
        for h in handles:
            h.remove()
    return [(conv, names[read[0]], read[0]) for conv, read in readers.items()
            if calls[conv] == 1 and len(read) == 1 and isinstance(read[0], nn.BatchNorm2d)]


def fold_batch_norms(model: nn.Module, example: torch.Tensor) -> int:
    """Fold every eval-mode batch norm fed by a convolution into it, in place; returns how many were folded.

    ``example`` is any input the model accepts (its values do not matter, only which module reads which)."""
    if model.training:
        raise ValueError("batch norms fold only into a network in eval mode")
    pairs = conv_norm_pairs(model, example)
    with torch.no_grad():
        for conv, norm_name, norm in pairs:
            scale = norm.weight / torch.sqrt(norm.running_var + norm.eps)
            bias = norm.bias - norm.running_mean * scale
            if conv.bias is not None:
                bias = bias + conv.bias * scale
            conv.weight.mul_(scale.view(-1, *([1] * (conv.weight.dim() - 1))))
            conv.bias = nn.Parameter(bias)
            parent_name, _, attr = norm_name.rpartition(".")
            parent = model.get_submodule(parent_name) if parent_name else model
            rest = AfterNorm(norm.drop, norm.act) if hasattr(norm, "act") else nn.Identity()
            setattr(parent, attr, rest)
    return len(pairs)
