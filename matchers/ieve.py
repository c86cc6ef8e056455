"""``ieve``: IEVE-style verification, a category detector opens a box and keypoint matches inside it are counted."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_match.contract import (
    Frames,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    get_matcher_class,
    register_matcher,
)
from pin_match.matchers.common.composite import CompositeMatcher, part_cfg_field


def gated_count(points: np.ndarray, boxes: np.ndarray | None, box_scores: np.ndarray | None,
                gate_sigma: float, gate: str) -> MatchResult:
    """IEVE's verdict: the keypoint matches inside the gate's best box, if that box reaches ``gate_sigma``.

    Score = their number (0 when the gate is closed); points = those matches; the box is kept.
    """
    if boxes is None or box_scores is None:
        raise MatcherError(f"matcher ieve: gate {gate!r} returns no boxes; choose a detector as the gate")
    box_scores = np.asarray(box_scores, np.float32).reshape(-1)
    if not len(box_scores) or box_scores.max() < gate_sigma:
        return MatchResult(score=0.0)
    best = int(np.argmax(box_scores))
    x0, y0, x1, y1 = np.asarray(boxes, np.float32).reshape(-1, 4)[best]
    points = np.asarray(points, np.float32).reshape(-1, 2)
    inside = (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)
    return MatchResult(score=float(inside.sum()), points=points[inside],
                       boxes=np.array([[x0, y0, x1, y1]], np.float32), box_scores=box_scores[best:best + 1])


@dataclass
class IeveConfig(MatcherConfig):
    gate: str = field(default="owl", metadata={"help": "registered matcher giving category boxes"})
    gate_cfg: dict[str, Any] = part_cfg_field("gate")
    gate_sigma: float = field(default=0.2, metadata={"help": "the gate's own box threshold (IEVE's detector)"})
    keypoints: str = field(default="disk-lightglue", metadata={
        "help": "registered matcher giving matched keypoints (IEVE: DISK + LightGlue)"})
    keypoints_cfg: dict[str, Any] = part_cfg_field("keypoints")


def category_query(gate: str) -> dict[str, str]:
    """The options that make a text detector ask for the category, as CoW and PIN do ("a photo of a {}.")."""
    fields = {f.name for f in dataclasses.fields(get_matcher_class(gate).Config)}
    options = {}
    if "query" in fields:
        options["query"] = "category"
    if "prompt" in fields:  # a category word alone is a poor query
        options["prompt"] = "a-photo-of"
    return options


@register_matcher("ieve")
class IeveMatcher(CompositeMatcher):
    """IEVE-style: a category detector opens a box, keypoint matches inside it are counted.

    Both parts are registered matchers built by name. A gate whose config has a ``query`` field
    (OWL) is switched to ``query="category"``, asked as CoW's "a photo of a {}.", and so reads
    the category label, which is why this matcher is of the category modality. The gate threshold
    is internal to the design (IEVE's detector has one); the final score, the match count, is
    still left un-thresholded. Each part keeps its own crop policy.
    """

    Config = IeveConfig
    modality = Modality.CATEGORY
    default_sigma = 100.0  # IEVE: > 100 matches confirm the goal (60: near it)
    paper = ("Lei et al., Instance-aware Exploration-Verification-Exploitation for Instance ImageGoal Navigation, "
             "CVPR 2024")

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self.gate = self.add_part("gate", self.cfg.gate, self.cfg.gate_cfg, category_query(self.cfg.gate))
        self.keypoints = self.add_part("keypoints", self.cfg.keypoints, self.cfg.keypoints_cfg)

    def _match_batch(self, frames: Frames) -> list[MatchResult]:
        gates = frames.results(self.gate)
        keypoints = frames.results(self.keypoints)
        return [gated_count(k.points, g.boxes, g.box_scores, self.cfg.gate_sigma, self.cfg.gate)
                for g, k in zip(gates, keypoints)]
