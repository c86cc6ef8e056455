"""The trained projection head and its checkpoint folder, shared by ``pin-match train`` and the ``learned`` matcher.

The head maps every patch token (frame and reference alike) before the prototype
matcher's own math: mask-weighted prototypes per reference view, cosine, max over views
and patches. It is residual with its last layer initialised to zero, so an untrained head
is exactly the identity and the learned matcher starts as the frozen prototype matcher
of the same backbone; training only has to learn the correction that separates the
user's instance from its look-alikes.

A head folder (``heads/NAME``) holds ``head.safetensors`` (the weights of the best epoch),
``config.json`` (architecture, the backbone matcher it was trained on, provenance, the
tuned sigma and the learning curves) and ``state.safetensors`` (what a killed run
resumes from).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from pin_match import atomic
from pin_match.errors import PinMatchError
from pin_match.nn.prototypes import masked_mean

HEAD_FORMAT = "pin-match-head"
HEAD_VERSION = 1
HEAD_FILE = "head.safetensors"
CONFIG_FILE = "config.json"
STATE_FILE = "state.safetensors"


class HeadError(PinMatchError, ValueError):
    """A head folder is missing, incomplete, or does not fit its backbone."""


class ProjectionHead(nn.Module):
    """x + W2 gelu(W1 LayerNorm(x)): a 2-layer residual MLP on patch tokens; W2 starts at zero (identity)."""

    def __init__(self, dim: int, hidden: int) -> None:
        super().__init__()
        self.dim, self.hidden = dim, hidden
        self.norm = nn.LayerNorm(dim)
        self.fc1 = nn.Linear(dim, hidden)
        self.fc2 = nn.Linear(hidden, dim)
        nn.init.zeros_(self.fc2.weight)
        nn.init.zeros_(self.fc2.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.fc2(F.gelu(self.fc1(self.norm(x))))


def prototypes(head: nn.Module, ref_tokens: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """Unit prototypes of projected reference tokens: (..., V, P, D), (..., V, P) -> (..., V, D).

    The mask-weighted mean (sum(alpha x token) / sum(alpha)) of the frozen matcher, on the
    head's output; only patches with alpha > 0 are projected, which is most of the saving.
    """
    flat_t, flat_a = ref_tokens.reshape(-1, *ref_tokens.shape[-2:]), alpha.reshape(-1, alpha.shape[-1])
    out = [masked_mean(head(tokens[weights > 0]), weights[weights > 0]) for tokens, weights in zip(flat_t, flat_a)]
    return F.normalize(torch.stack(out), dim=-1).reshape(*ref_tokens.shape[:-2], ref_tokens.shape[-1])


class HeadBackbone:
    """A ``PatchBackbone`` whose patch tokens went through the head: the prototype matcher runs on it unchanged."""

    def __init__(self, base, head: ProjectionHead) -> None:
        self.base, self.head = base, head.eval()
        self.input_size, self.grid = base.input_size, base.grid

    @torch.inference_mode()
    def encode(self, images: Sequence[np.ndarray]):
        feats = self.base.encode(images)
        feats.patches = self.head(feats.patches.float())
        return feats


def save_head(folder: str | Path, head: ProjectionHead, config: dict) -> None:
    """Write the weights, then the config (each atomically): a reader never sees a config without its weights."""
    from safetensors.torch import save

    folder = atomic.ensure_dir(folder)
    tensors = {k: v.detach().contiguous().clone() for k, v in head.state_dict().items()}
    atomic.write_bytes(folder / HEAD_FILE, save(tensors, metadata={"format": HEAD_FORMAT}))
    atomic.write_text(folder / CONFIG_FILE, json.dumps(config, indent=2, default=str) + "\n")


def read_head_config(folder: str | Path) -> dict:
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        raise HeadError(f"{folder} is not a head folder (no {CONFIG_FILE}); train one with pin-match train")
    config = atomic.read_json(path, HeadError)
    if config.get("format") != HEAD_FORMAT or not isinstance(config.get("version"), int) \
            or config["version"] > HEAD_VERSION:
        raise HeadError(f"{path} is not a {HEAD_FORMAT} config of version <= {HEAD_VERSION}")
    return config


def load_head(folder: str | Path) -> tuple[ProjectionHead, dict]:
    """The trained head (eval mode, CPU) and its config."""
    from safetensors.torch import load_file

    config = read_head_config(folder)
    path = Path(folder) / HEAD_FILE
    if not path.is_file():
        raise HeadError(f"head folder {folder} has {CONFIG_FILE} but no {HEAD_FILE}")
    head = ProjectionHead(int(config["head"]["dim"]), int(config["head"]["hidden"]))
    try:
        head.load_state_dict(load_file(str(path)))
    except (RuntimeError, OSError, ValueError) as exc:
        reason = next((x.strip() for x in str(exc).splitlines() if x.strip()), type(exc).__name__)
        raise HeadError(f"{path} does not fit the head described in {CONFIG_FILE} ({reason})") from exc
    return head.eval(), config
