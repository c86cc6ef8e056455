"""``superglue``: PIN's baseline, SuperPoint + SuperGlue against the six prepared references.

SuperGlue's matching stage is run here from the transformers model's public modules, one
observation-reference pair at a time on its real keypoints (``superglue_pair``), as
magicleap's SuperGlue does, so the optimal transport's marginals are the pair's real counts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from pin_match.contract import ConfigError, MatchResult, Modality, WeightsSpec, register_matcher
from pin_match.matchers.common.keypoints import (
    CombineConfig,
    Keypoints,
    PairMatches,
    combined_verdict,
    confidence_sum,
    mutual_matches,
    normalize_keypoints,
)
from pin_match.matchers.common.superpoint import SuperPointConfig, SuperPointGlueMatcher

SUPERGLUE_WEIGHTS = WeightsSpec("magic-leap-community/superglue_indoor",
                                license="Magic Leap non-commercial research license (SuperPoint and SuperGlue)")


def log_optimal_transport(scores: torch.Tensor, bin_score: torch.Tensor, iterations: int) -> torch.Tensor:
    """SuperGlue's entropic optimal transport of one pair's ``(m, n)`` scores, with a dustbin row and column.

    The marginals come from this pair's own m and n, as in the original SuperGlue: every
    keypoint has mass 1 / (m + n), the dustbins n / (m + n) and m / (m + n). Padding the
    block to a batch's largest keypoint count changes them, and with the 20 Sinkhorn
    iterations PIN runs that lowers the confidences by several percent. Log-space Sinkhorn;
    returns the ``(m + 1, n + 1)`` log assignment multiplied by m + n.
    """
    m, n = scores.shape
    alpha = bin_score.to(scores).reshape(1, 1)
    couplings = torch.cat([torch.cat([scores, alpha.expand(m, 1)], 1), torch.cat([alpha.expand(1, n), alpha], 1)], 0)
    norm = -math.log(m + n)
    log_mu = torch.cat([scores.new_full((m,), norm), scores.new_tensor([math.log(n) + norm])])
    log_nu = torch.cat([scores.new_full((n,), norm), scores.new_tensor([math.log(m) + norm])])
    u, v = torch.zeros_like(log_mu), torch.zeros_like(log_nu)
    for _ in range(iterations):
        u = log_mu - torch.logsumexp(couplings + v[None, :], dim=1)
        v = log_nu - torch.logsumexp(couplings + u[:, None], dim=0)
    return couplings + u[:, None] + v[None, :] - norm


def superglue_pair(model: torch.nn.Module, obs: Keypoints, ref: Keypoints, iterations: int,
                   threshold: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """SuperGlue on one pair of unpadded keypoint sets, with the transformers model's public modules.

    Keypoint encoder, self / cross attention layers updating both sets at once, final
    projection, scores / sqrt(D), optimal transport on the real m x n block, then
    ``mutual_matches``. Returns ``(matches0 (m,), matches1 (n,), confidence0 (m,))``.
    """
    desc = [k.descriptors[None] + model.keypoint_encoder(normalize_keypoints(k.xy, k.height, k.width, 0.7)[None],
                                                        k.scores[None])[0] for k in (obs, ref)]
    for layer, kind in zip(model.gnn.layers, model.gnn.layers_types):
        sources = desc[::-1] if kind == "cross" else desc
        desc = [d + layer(d, encoder_hidden_states=src)[0] for d, src in zip(desc, sources)]
    proj0, proj1 = (model.final_projection(d)[0] for d in desc)
    log_p = log_optimal_transport(proj0 @ proj1.T / proj0.shape[-1] ** 0.5, model.bin_score, iterations)[:-1, :-1]
    return mutual_matches(log_p, threshold)


@dataclass
class SuperGlueMatcherConfig(SuperPointConfig, CombineConfig):
    """PIN's settings; ``combine="sum"`` is PIN's "sum of confidences" as read here."""

    sinkhorn_iterations: int = field(default=20, metadata={"help": "optimal transport iterations (PIN's 20)"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.sinkhorn_iterations < 0:
            raise ConfigError(f"sinkhorn_iterations={self.sinkhorn_iterations}: must be >= 0")


@register_matcher("superglue")
class SuperGlueMatcher(SuperPointGlueMatcher):
    """PIN's SuperGlue baseline: score = sum of the confidences of the valid matches over the six references."""

    Config = SuperGlueMatcherConfig
    modality = Modality.VISUAL
    default_sigma = 8.0
    weights_spec = SUPERGLUE_WEIGHTS
    paper = "Sarlin et al., SuperGlue: Learning Feature Matching with Graph Neural Networks, CVPR 2020"
    version = 3  # what each version changed: docs/baselines.md
    transformers_classes = ("SuperGlueConfig", "SuperGlueForKeypointMatching")

    def _match_pair(self, obs: Keypoints, ref: Keypoints) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return superglue_pair(self._model, obs, ref, self.cfg.sinkhorn_iterations, self.cfg.match_threshold)

    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult:
        return combined_verdict(pairs, obs_xy, self.cfg.combine, confidence_sum)
