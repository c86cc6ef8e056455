"""The training loss: class-balanced BCE on patches and on crops (the module docstring of ``loop`` says why)."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from pin_match.nn.head import ProjectionHead, prototypes
from pin_match.nn.prototypes import patch_scores
from pin_match.training.config import TrainConfig
from pin_match.training.data import TrainData


def batch_loss(head: ProjectionHead, scale: torch.Tensor, bias: torch.Tensor, data: TrainData,
               crop_idx: np.ndarray, cfg: TrainConfig) -> torch.Tensor:
    """The two BCE terms (see the module docstring) for one step's crops, all of one episode."""
    store = data.store
    episode = str(store.crops.episode_id.iloc[int(crop_idx[0])])
    query = [u for u in data.queries[episode] if u in data.fit_objects]
    tokens = torch.from_numpy(np.asarray(store.frames[crop_idx], np.float32))            # (B, P, D)
    obj = torch.from_numpy(np.asarray(store.patch_object[crop_idx], np.int64))           # (B, P)
    cover = torch.from_numpy(np.asarray(store.patch_cover[crop_idx], np.float32))        # (B, P)
    refs = torch.from_numpy(np.asarray(store.refs[query], np.float32))                   # (Q, V, P, D)
    alpha = torch.from_numpy(np.asarray(store.ref_alpha[query], np.float32))             # (Q, V, P)

    sims = patch_scores(head(tokens), prototypes(head, refs, alpha))                     # (B, P, Q)
    logits = scale * (sims - bias)

    on_held = torch.isin(obj, torch.tensor(sorted(data.holdout_objects), dtype=torch.int64))
    on_episode = torch.isin(obj, torch.tensor(data.queries[episode], dtype=torch.int64))
    sums, counts = torch.zeros(3), torch.zeros(3)  # positives, hard negatives, other negatives
    crop_sums, crop_counts = torch.zeros(3), torch.zeros(3)  # crops: query shown, only a sibling shown, neither
    for k, u in enumerate(query):
        lk, on_u = logits[..., k], obj == u
        groups = (on_u & (cover >= cfg.min_cover), on_episode & ~on_u & ~on_held, ~on_episode & ~on_held)
        for g, (mask, label) in enumerate(zip(groups, (1.0, 0.0, 0.0))):
            values = lk[mask]
            sums = sums.index_add(0, torch.tensor([g]), F.binary_cross_entropy_with_logits(
                values, torch.full_like(values, label), reduction="sum").reshape(1))
            counts[g] += values.numel()
        present, absent = groups[0].any(1), ~on_u.any(1)  # a crop where u shows only a sliver is left out
        sibling = absent & groups[1].any(1)
        crop_logit = lk.masked_fill(on_held, -1e4).amax(1)
        for g, (mask, label) in enumerate(zip((present, sibling, absent & ~sibling), (1.0, 0.0, 0.0))):
            values = crop_logit[mask]
            crop_sums = crop_sums.index_add(0, torch.tensor([g]), F.binary_cross_entropy_with_logits(
                values, torch.full_like(values, label), reduction="sum").reshape(1))
            crop_counts[g] += values.numel()
    return (sums / counts.clamp(min=1)).sum() + (crop_sums / crop_counts.clamp(min=1)).sum()
