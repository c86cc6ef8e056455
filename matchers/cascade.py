"""``parts-cascade``: a patch score verified by keypoint matches.

Keypoint matchers (``sift``, ``xfeat``, DISK + LightGlue) rarely fire, but when they do they
are strong evidence of the very instance: a look-alike of the same category has other
texture, print and wear, so its keypoints do not match the references'. Patch similarity is
the opposite: it always answers, and look-alikes score close to the target. The cascade adds
the keypoint evidence on top of the patch score:

    score = patch score + weight x log(1 + keypoint score)

so a frame without keypoint matches keeps its patch score and every match raises it, with
diminishing returns (ten matches are much more than none, 110 little more than 100). Both
parts are registered matchers built by name, each with its own crop policy; their ids enter
this matcher's id.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pin_match.contract import (
    ConfigError,
    Matcher,
    MatcherConfig,
    MatchResult,
    Modality,
    Target,
    WeightsError,
    create_matcher,
    parse_overrides,
    register_matcher,
)


def part_overrides(text: str, option: str) -> dict[str, str]:
    """``"layer=head,img_size=448"`` into overrides for a part; ConfigError naming the option when malformed."""
    try:
        return parse_overrides([p for p in text.split(",") if p.strip()])
    except ConfigError as exc:
        raise ConfigError(f"{option}={text!r}: {exc}") from exc


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
    patch_cfg: str = field(default="", metadata={"help": "its config, key=value,key=value"})
    keypoints: str = field(default="xfeat", metadata={"help": "registered matcher counting matched keypoints"})
    keypoints_cfg: str = field(default="", metadata={"help": "its config, key=value,key=value"})
    weight: float = field(default=0.02, metadata={"help": "score = patch + weight x log(1 + keypoint score)"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if "parts-cascade" in (self.patch, self.keypoints):
            raise ConfigError("matcher parts-cascade cannot use itself as a part")
        if not (math.isfinite(self.weight) and self.weight >= 0):
            raise ConfigError(f"{type(self).__name__}: weight={self.weight} must be finite and >= 0")


@register_matcher("parts-cascade")
class PartsCascadeMatcher(Matcher):
    """Patch score plus weight x log(1 + matched keypoints) (see module doc)."""

    Config = CascadeConfig
    modality = Modality.VISUAL
    # F1 on the real look-alike set's train instances, both variants at once (23.3 shot / 45.8 pasted; 0.65 matched
    # almost no target: 14.3 / 0.0)
    default_sigma = 0.374
    version = 1
    paper = "pin_match: keypoint verification on a part-matching score (issue 21)"

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self.patch = create_matcher(self.cfg.patch, **part_overrides(self.cfg.patch_cfg, "patch_cfg"))
        self.keypoints = create_matcher(self.cfg.keypoints, **part_overrides(self.cfg.keypoints_cfg, "keypoints_cfg"))
        for role, part in self.parts().items():
            if part.modality is not Modality.VISUAL:
                raise ConfigError(f"matcher parts-cascade: {role} part {part.display_name!r} is of the "
                                  f"{part.modality.value} modality; the cascade needs visual parts")

    def parts(self) -> dict[str, Matcher]:
        return {"patch": self.patch, "keypoints": self.keypoints}

    def _prepare(self, target: Target) -> None:
        for role, part in self.parts().items():
            try:
                part.prepare(target)
            except WeightsError as exc:
                raise WeightsError(f"matcher parts-cascade, {role} part {part.display_name!r} (set {role}_cfg="
                                   f"weights=...): {exc}") from exc

    def _match_batch(self, images: list[np.ndarray]) -> list[MatchResult]:
        patches = self.patch.match_batch(images)
        keypoints = self.keypoints.match_batch(images)
        return [cascade_result(p, k, self.cfg.weight) for p, k in zip(patches, keypoints)]
