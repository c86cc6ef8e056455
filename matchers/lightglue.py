"""LightGlue's layers for one pair of unpadded keypoint sets, and ``lightglue``: SuperPoint + LightGlue.

LightGlue (Lindenberger et al., ICCV 2023; cvg/LightGlue's lightglue.py) runs here from the
transformers model's layers. transformers' own pair matching (``_match_image_pair``) is private
and pads every pair of a batch to one keypoint count; its attention modules reshape keys with
the queries' length, so they cannot take two images with different counts either. The
attention below reads their projections.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from pin_match.contract import MatchResult, Modality, WeightsSpec, register_matcher
from pin_match.matchers.common.keypoints import (
    Keypoints,
    PairMatches,
    count_verdict,
    mutual_matches,
    normalize_keypoints,
)
from pin_match.matchers.common.superpoint import SuperPointConfig, SuperPointGlueMatcher

LIGHTGLUE_WEIGHTS = WeightsSpec("ETH-CVG/lightglue_superpoint",
                                license="Apache-2.0 (LightGlue); SuperPoint's Magic Leap non-commercial license")


def lightglue_attention(attention: torch.nn.Module, x: torch.Tensor, source: torch.Tensor,
                        rotary: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
    """Multi-head attention of ``x`` (n, D) over ``source`` (m, D); ``rotary`` = (cos, sin) of both (self-attention)."""
    q, k, v = (proj(t).unflatten(-1, (-1, attention.head_dim)).transpose(0, 1)
               for proj, t in ((attention.q_proj, x), (attention.k_proj, source), (attention.v_proj, source)))
    k, v = (t.repeat_interleave(attention.num_key_value_groups, dim=0) for t in (k, v))  # grouped key heads
    if rotary is not None:
        cos, sin = rotary
        q, k = (t * cos + rotate_half(t) * sin for t in (q, k))
    weights = torch.softmax(q @ k.transpose(-1, -2) * q.shape[-1] ** -0.5, dim=-1)
    return attention.o_proj((weights @ v).transpose(0, 1).flatten(-2))


def rotate_half(x: torch.Tensor) -> torch.Tensor:
    """LightGlue's rotary pairing: (x0, x1, x2, x3...) -> (-x1, x0, -x3, x2...)."""
    pairs = x.unflatten(-1, (-1, 2))
    return torch.stack((-pairs[..., 1], pairs[..., 0]), dim=-1).flatten(-2)


def lightglue_layer(layer: torch.nn.Module, desc: list[torch.Tensor],
                    rotary: list[tuple[torch.Tensor, torch.Tensor]]) -> list[torch.Tensor]:
    """One LightGlue layer: self-attention in each image, then cross-attention both ways, each with its MLP."""
    desc = [d + layer.self_mlp(torch.cat([d, lightglue_attention(layer.self_attention, d, d, r)], -1))
            for d, r in zip(desc, rotary)]
    return [d + layer.cross_mlp(torch.cat([d, lightglue_attention(layer.cross_attention, d, src)], -1))
            for d, src in zip(desc, desc[::-1])]


def lightglue_log_assignment(assignment: torch.Tensor, desc0: torch.Tensor, desc1: torch.Tensor) -> torch.Tensor:
    """LightGlue's ``(m, n)`` log assignment: double softmax of the similarity plus both matchabilities."""
    proj0, proj1 = (assignment.final_projection(d) / d.shape[-1] ** 0.25 for d in (desc0, desc1))
    sim = proj0 @ proj1.T
    z0, z1 = assignment.matchability(desc0), assignment.matchability(desc1)
    certainty = torch.nn.functional.logsigmoid(z0) + torch.nn.functional.logsigmoid(z1).T
    return sim.log_softmax(1) + sim.log_softmax(0) + certainty


def lightglue_confidence_threshold(layer: int, layers: int) -> float:
    return min(max(0.8 + 0.1 * math.exp(-4.0 * layer / layers), 0.0), 1.0)


def lightglue_inputs(model: torch.nn.Module, k: Keypoints) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
    """One image's projected descriptors and the rotary encoding (cos, sin) of its normalised keypoints."""
    angles = model.positional_encoder.projector(normalize_keypoints(k.xy, k.height, k.width, 0.5))
    angles = angles.repeat_interleave(2, dim=-1)
    return model.input_projection(k.descriptors), (angles.cos(), angles.sin())


def lightglue_pair(model: torch.nn.Module, obs: Keypoints, ref: Keypoints,
                   threshold: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """LightGlue on one pair of unpadded keypoint sets, with its adaptive depth and width as in cvg/LightGlue on CPU.

    After each layer but the last: stop when more than ``depth_confidence`` of both images' keypoints are
    confident; otherwise drop keypoints whose matchability is at most 1 - ``width_confidence`` unless their
    confidence is low (cvg prunes at any count on CPU; on CUDA only above 1024 keypoints, which the matcher does
    not copy, so results do not depend on the device). The assignment of the layer reached gives the matches.
    Returns ``(matches0 (m,), matches1 (n,), confidence0 (m,))`` in the input order.
    """
    cfg = model.config
    layers = cfg.num_hidden_layers
    m, n = len(obs.xy), len(ref.xy)
    index = [torch.arange(m, device=obs.xy.device), torch.arange(n, device=obs.xy.device)]
    (d0, r0), (d1, r1) = lightglue_inputs(model, obs), lightglue_inputs(model, ref)
    desc, rotary = [d0, d1], [r0, r1]
    for i in range(layers):
        if not len(index[0]) or not len(index[1]):
            break
        desc = lightglue_layer(model.transformer_layers[i], desc, rotary)
        if i == layers - 1:
            break
        confident = lightglue_confidence_threshold(i, layers)
        tokens = [model.token_confidence[i](d) for d in desc] if cfg.depth_confidence > 0 else [None, None]
        if cfg.depth_confidence > 0:
            unsure = sum(int((t < confident).sum()) for t in tokens)
            if 1.0 - unsure / (m + n) > cfg.depth_confidence:
                break
        if cfg.width_confidence > 0:
            for side in (0, 1):
                keep = model.match_assignment_layers[i].get_matchability(desc[side]) > 1 - cfg.width_confidence
                if tokens[side] is not None:
                    keep |= tokens[side] <= confident
                index[side], desc[side] = index[side][keep], desc[side][keep]
                rotary[side] = tuple(t[..., keep, :] for t in rotary[side])
    matches0 = obs.xy.new_full((m,), -1, dtype=torch.long)
    matches1 = obs.xy.new_full((n,), -1, dtype=torch.long)
    conf0 = obs.xy.new_zeros(m)
    if len(index[0]) and len(index[1]):
        m0, m1, c0 = mutual_matches(lightglue_log_assignment(model.match_assignment_layers[i], *desc), threshold)
        matches0[index[0]] = torch.where(m0 >= 0, index[1][m0.clamp(min=0)], -1)
        matches1[index[1]] = torch.where(m1 >= 0, index[0][m1.clamp(min=0)], -1)
        conf0[index[0]] = c0
    return matches0, matches1, conf0



@dataclass
class LightGlueMatcherConfig(SuperPointConfig):
    match_threshold: float = field(default=0.1, metadata={"help": "LightGlue's own filter threshold"})


@register_matcher("lightglue")
class LightGlueMatcher(SuperPointGlueMatcher):
    """SuperPoint + LightGlue against PIN's six references; score = number of observation keypoints matched to
    the object (distinct keypoints, so one seen in several references counts once)."""

    Config = LightGlueMatcherConfig
    modality = Modality.VISUAL
    default_sigma = 100.0  # IEVE's "confirmed" match count
    weights_spec = LIGHTGLUE_WEIGHTS
    paper = "Lindenberger et al., LightGlue: Local Feature Matching at Light Speed, ICCV 2023"
    version = 2  # what each version changed: docs/baselines.md
    transformers_classes = ("LightGlueConfig", "LightGlueForKeypointMatching")

    def _match_pair(self, obs: Keypoints, ref: Keypoints) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return lightglue_pair(self._model, obs, ref, self.cfg.match_threshold)

    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult:
        return count_verdict(pairs, obs_xy)
