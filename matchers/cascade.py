"""``parts-cascade``: a patch score verified by keypoint matches.

Keypoint matchers (``sift``, ``xfeat``, DISK + LightGlue) rarely fire, but when they do they
are strong evidence of the very instance: a look-alike of the same category has other
texture, print and wear, so its keypoints do not match the references'. Patch similarity is
the opposite: it always answers, and look-alikes score close to the target. The cascade adds
the keypoint evidence on top of the patch score:

    score = patch score + weight x log(1 + keypoint score)

so a frame without keypoint matches keeps its patch score and every match raises it, with
diminishing returns (ten matches are much more than none, 110 little more than 100). Both
parts are registered matchers built by name, each with its own config (``--cfg
patch_cfg.img_size=448``) and crop policy; their ids enter this matcher's id.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_match.contract import ConfigError, Frames, MatcherConfig, MatchResult, Modality, register_matcher
from pin_match.matchers.common.composite import CompositeMatcher, part_cfg_field


def keypoint_bonus(keypoint_score: float, weight: float) -> float:
    """What the keypoint evidence adds: weight x log(1 + matches) (0 for no match)."""
    return weight * math.log1p(max(float(keypoint_score), 0.0))


def cascade_result(patch: MatchResult, keypoints: MatchResult, weight: float) -> MatchResult:
    """The combined verdict: the patch points raised by the bonus, plus the matched keypoints at the frame score.

    Raising every patch point by the same bonus keeps the frame score the max of the point map.
    """
    bonus = keypoint_bonus(keypoints.score, weight)
    score = float(patch.score) + bonus
    points = np.concatenate([patch.points, keypoints.points])
    point_scores = np.concatenate([patch.scores_of_points() + bonus,
                                   np.full(len(keypoints.points), score, np.float32)])
    return MatchResult(score=score, points=points, point_scores=point_scores)


@dataclass
class CascadeConfig(MatcherConfig):
    patch: str = field(default="effnet-parts", metadata={"help": "registered matcher giving the patch score"})
    patch_cfg: dict[str, Any] = part_cfg_field("patch")
    keypoints: str = field(default="xfeat", metadata={"help": "registered matcher counting matched keypoints"})
    keypoints_cfg: dict[str, Any] = part_cfg_field("keypoints")
    weight: float = field(default=0.02, metadata={"help": "score = patch + weight x log(1 + keypoint score)"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (math.isfinite(self.weight) and self.weight >= 0):
            raise ConfigError(f"{type(self).__name__}: weight={self.weight} must be finite and >= 0")


@register_matcher("parts-cascade")
class PartsCascadeMatcher(CompositeMatcher):
    """Patch score plus weight x log(1 + matched keypoints) (see module doc)."""

    Config = CascadeConfig
    modality = Modality.VISUAL
    # tuned on the real look-alike set's train instances (docs/instance-matchers.md)
    default_sigma = 0.374
    version = 1
    paper = "pin_match: keypoint verification on a part-matching score"

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self.patch = self.add_part("patch", self.cfg.patch, self.cfg.patch_cfg)
        self.keypoints = self.add_part("keypoints", self.cfg.keypoints, self.cfg.keypoints_cfg)
        self.require_visual()

    def _match_batch(self, frames: Frames) -> list[MatchResult]:
        patches = frames.results(self.patch)
        keypoints = frames.results(self.keypoints)
        return [cascade_result(p, k, self.cfg.weight) for p, k in zip(patches, keypoints)]
