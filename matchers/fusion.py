"""``fusion``: a learned linear combination of registered matchers' scores, read from a fusion file.

No one matcher separates an instance from its look-alikes everywhere: part matching, the
prototype, colour and keypoints each fail on different pairs. A fusion file (written by
``pin_match.fitting.fusion.fit_fusion`` from cached score tables of a train split) names
the component matchers with their configs and ids, a transform per component (``identity``,
or ``log1p`` for match counts), and the weights of a logistic regression fitted there:

    score = intercept + sum_i coef_i x transform_i(score_i)

i.e. the logit of "this frame shows the target"; it is never thresholded here. The matcher
id hashes the file's content (and the components' ids), so a refitted file never reads a
stale cache, and a component whose id changed since the fit (other weights or code
version) is refused instead of being fed to weights fitted on other scores. Points are those
of the ``points_from`` component, shifted by (fused score - its score) so the frame score
stays the max of the point map. With no ``weights=`` the file fitted on the look-alike
development frame-sets (docs/instance-matchers.md) is used.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pin_match.contract import (
    Frames,
    Matcher,
    MatcherConfig,
    MatchResult,
    Modality,
    WeightsError,
    register_matcher,
    weights_field,
)
from pin_match.matchers.common.composite import CompositeMatcher
from pin_match.matchers.common.fitted import FittedFileSpec
from pin_match.matchers.common.fusion_file import TRANSFORMS, read_fusion


def fused_score(spec: dict[str, Any], scores: list[float]) -> float:
    """intercept + sum coef x transform(score), the rule the fit optimised."""
    return float(spec["intercept"]) + sum(float(c["coef"]) * TRANSFORMS[c["transform"]](float(s))
                                          for c, s in zip(spec["components"], scores))


@dataclass
class FusionConfig(MatcherConfig):
    weights: str | None = weights_field()


@register_matcher("fusion")
class FusionMatcher(CompositeMatcher):
    """Logistic-regression fusion of component matchers' scores, weights from a fusion file (see module doc)."""

    Config = FusionConfig
    modality = Modality.VISUAL
    weights_spec = FittedFileSpec(package="pin_match.matchers", package_file="fusion_lookalike.json",
                                  distribution="pin-match",
                                  license="the fusion file's own: weights fitted by pin_match (MIT)")
    default_sigma = 0.0  # the logit at probability 1/2 under the fitting's class weights
    version = 1
    paper = "pin_match: score fusion fitted on a train split of real look-alikes"

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self.path = self.weights_spec.resolve(self.cfg.weights, f"matcher {self.display_name}")
        self.spec = read_fusion(self.path)
        self.components = [self._component(i, c) for i, c in enumerate(self.spec["components"])]
        self.require_visual(f"fusion file {self.path}", WeightsError)

    def _component(self, i: int, c: dict[str, Any]) -> Matcher:
        part = self.add_part(f"{i}:{c['matcher']}", c["matcher"], dict(c.get("config") or {}))
        if part.id != c.get("id"):
            raise WeightsError(f"fusion file {self.path}: component {i} was fitted as {c.get('id')}, but "
                               f"{c['matcher']} with its recorded config is now {part.id} (other weights or code "
                               f"version): refit the fusion")
        return part

    def weights_hint(self, role: str) -> str:
        return f"its config in the fusion file {self.path}"

    def _match_batch(self, frames: Frames) -> list[MatchResult]:
        per_part = [frames.results(part) for part in self.components]
        anchor = int(self.spec["points_from"])
        out = []
        for k in range(len(frames)):
            results = [r[k] for r in per_part]
            score = fused_score(self.spec, [r.score for r in results])
            shown = results[anchor]
            shift = score - float(shown.score)
            out.append(MatchResult(score=score, points=shown.points, point_scores=shown.scores_of_points() + shift))
        return out
