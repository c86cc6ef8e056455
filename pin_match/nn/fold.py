"""Batch norms folded into the convolutions that feed them, for networks that only ever run in eval mode.

In eval mode a batch norm is a per-channel scale and shift: the convolution before it can
apply both through its weights and bias, and the norm's own pass over the activations goes.
On the CPU that pass is memory-bound and cost about half as much as the convolutions of the
EfficientNet trunks (docs/performance.md). The folded network computes the same function up to
float rounding.

Which convolution feeds which norm is read from one forward pass (hooks), not from module
names, so timm's and torchvision's layouts fold alike; a norm whose input is not the output of
a convolution run once (or that convolution's output also read by another module) stays as it is,
and so does a norm that divides by each batch's own statistics (no running statistics, or left in
training mode), which no fixed weight can hold; one without affine weights scales by 1 and shifts
by 0. Hooks see modules only: a plain function (``torch.relu(y)``, ``y * 2``) that also reads the
convolution's output is invisible to them, and folding would change what it reads. So the
network's output on the example, from that same pass, is compared with its output once folded;
where they differ beyond ``TOLERANCE`` the network is put back as it was, with a warning, and runs
unfolded: folding only saves time, so the safe answer to a doubt is the slower, unchanged network,
never a different one, nor a refusal of a network that works.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

# the largest output difference a fold may make, relative to the output's largest magnitude (at least 1): float
# rounding of a folded EfficientNet trunk is some 1e-5 of it (docs/performance.md), a changed function far more
TOLERANCE = 1e-3


class FoldWarning(UserWarning):
    """Folding was undone: the folded network's output differed from the original's."""


class AfterNorm(nn.Module):
    """What is left of a norm-plus-activation module (timm's ``BatchNormAct2d``) once its norm is folded."""

    def __init__(self, drop: nn.Module, act: nn.Module) -> None:
        super().__init__()
        self.drop, self.act = drop, act

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.act(self.drop(x))


@dataclass
class Fold:
    """One norm folded into its convolution, with what it replaced: enough to put the network back."""

    conv: nn.Conv2d
    weight: nn.Parameter
    bias: nn.Parameter | None
    parent: nn.Module
    attr: str
    norm: nn.BatchNorm2d

    def undo(self) -> None:
        self.conv.weight, self.conv.bias = self.weight, self.bias
        setattr(self.parent, self.attr, self.norm)


def fixed(norm: nn.BatchNorm2d) -> bool:
    """Whether the norm is a fixed per-channel scale and shift: it reads running statistics, not the batch's."""
    return not norm.training and norm.running_mean is not None and norm.running_var is not None


def conv_norm_pairs(model: nn.Module, example: torch.Tensor) -> tuple[list[tuple[nn.Conv2d, str, nn.BatchNorm2d]], Any]:
    """(conv, norm name, norm) for every fixed norm that reads a convolution's output and no other module does, and
    the model's output on ``example`` (the pass the hooks watched)."""
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
            output = model(example)
    finally:
        for h in handles:
            h.remove()
    pairs = [(conv, names[read[0]], read[0]) for conv, read in readers.items()
             if calls[conv] == 1 and len(read) == 1 and isinstance(read[0], nn.BatchNorm2d) and fixed(read[0])]
    return pairs, output


def fold_one(model: nn.Module, conv: nn.Conv2d, norm_name: str, norm: nn.BatchNorm2d) -> Fold:
    """Fold ``norm`` into ``conv`` and take it out of ``model``. The folded weights are new parameters, so the
    originals (and any module sharing them) stay as they were, to be put back by ``Fold.undo``."""
    scale = torch.rsqrt(norm.running_var + norm.eps)
    if norm.weight is not None:
        scale = scale * norm.weight
    bias = -norm.running_mean * scale
    if norm.bias is not None:
        bias = bias + norm.bias
    if conv.bias is not None:
        bias = bias + conv.bias * scale
    parent_name, _, attr = norm_name.rpartition(".")
    parent = model.get_submodule(parent_name) if parent_name else model
    done = Fold(conv, conv.weight, conv.bias, parent, attr, norm)
    conv.weight = nn.Parameter(conv.weight * scale.view(-1, *([1] * (conv.weight.dim() - 1))),
                               requires_grad=conv.weight.requires_grad)
    conv.bias = nn.Parameter(bias, requires_grad=conv.weight.requires_grad)
    setattr(parent, attr, AfterNorm(norm.drop, norm.act) if hasattr(norm, "act") else nn.Identity())
    return done


def tensors(output: Any) -> Iterator[torch.Tensor]:
    """Every tensor of a model's output: a tensor, or lists, tuples and dicts of them (timm's feature lists)."""
    if isinstance(output, torch.Tensor):
        yield output
    elif isinstance(output, dict):
        yield from tensors(list(output.values()))
    elif isinstance(output, (list, tuple)):
        for item in output:
            yield from tensors(item)


def difference(before: Any, after: Any) -> float:
    """The largest difference of two outputs, relative to each tensor's largest magnitude (at least 1); infinite
    when they are not alike in shape."""
    old, new = list(tensors(before)), list(tensors(after))
    if len(old) != len(new) or any(a.shape != b.shape for a, b in zip(old, new)):
        return float("inf")
    return max((float((b - a).abs().max()) / max(1.0, float(a.abs().max())) for a, b in zip(old, new) if a.numel()),
               default=0.0)


def fold_batch_norms(model: nn.Module, example: torch.Tensor) -> int:
    """Fold every fixed eval-mode batch norm fed by a convolution into it, in place; returns how many were folded.

    ``example`` is any input the model accepts. Which module reads which is read from one pass
    on it, and the outputs before and after folding are compared on it: a random input tests that
    comparison better than zeros, which many networks map to constants. Where they differ by more
    than ``TOLERANCE`` (a plain function read a convolution's output) every fold is undone, a
    ``FoldWarning`` says so, and 0 is returned: the network computes what it did, unfolded.
    """
    if model.training:
        raise ValueError("batch norms fold only into a network in eval mode")
    pairs, before = conv_norm_pairs(model, example)
    with torch.no_grad():
        done = [fold_one(model, conv, norm_name, norm) for conv, norm_name, norm in pairs]
    if not done:
        return 0
    with torch.inference_mode():
        after = model(example)
    changed = difference(before, after)
    if changed > TOLERANCE:
        for fold in reversed(done):
            fold.undo()
        warnings.warn(f"{type(model).__name__}: folding {len(done)} batch norms changed its output by {changed:.3g} "
                      f"(relative, over {TOLERANCE:g}): something other than a module, such as a plain function, reads "
                      f"a convolution's output; the network is left unfolded (same output, without the speed-up)",
                      FoldWarning, stacklevel=2)
        return 0
    return len(done)

