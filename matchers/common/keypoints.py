"""What every keypoint matcher shares: PIN's match rule, the verdicts, the config and the reference loop.

A keypoint matcher finds keypoints in PIN's six prepared references once per target
(``pin_match.matchers.common.references``) and in each frame, pairs the frame with each reference
on its own (so a pair's match confidences depend on its own keypoints only), keeps PIN's
valid matches (mutual, confidence above the threshold) and turns them into a verdict. Only
the keypoint detector and the pairing differ between SuperGlue, LightGlue, DISK, ALIKED and
XFeat; they live in their own modules.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import torch

from pin_match.contract import (
    ConfigError,
    CropConfig,
    CropMatcher,
    MatcherConfig,
    MatchResult,
    Target,
    crops_field,
    weights_field,
)
from pin_match.matchers.common.references import prepare_references

COMBINE = ("sum", "max")  # how the six references' evidence becomes the frame score


@dataclass
class Keypoints:
    """One image's keypoints, in that image's pixels; ``scores`` only where the pairing reads them (SuperGlue)."""

    xy: torch.Tensor           # (N, 2) x, y
    descriptors: torch.Tensor  # (N, D)
    height: int
    width: int
    scores: torch.Tensor | None = None  # (N,)


@dataclass
class PairMatches:
    """The valid matches of one observation-reference pair."""

    obs_index: np.ndarray   # (M,) observation keypoints with a valid match
    confidence: np.ndarray  # (M,) their match confidences
    on_object: np.ndarray   # (M,) bool: the matched reference keypoint lies inside the reference mask


def valid_matches(matches0: np.ndarray, matches1: np.ndarray, confidence0: np.ndarray, ref_xy: np.ndarray,
                  ref_mask: np.ndarray, threshold: float) -> PairMatches:
    """PIN's rule: a match is valid when it is mutual and its confidence exceeds ``threshold``.

    ``matches0[i]`` is the reference keypoint matched to observation keypoint ``i`` (-1: none),
    ``matches1[j]`` the observation keypoint matched to reference keypoint ``j``; indices past
    the reference's real keypoints (padding) never count.
    """
    m0 = np.asarray(matches0, np.int64)
    m1 = np.asarray(matches1, np.int64)
    conf = np.asarray(confidence0, np.float32)
    known = (m0 >= 0) & (m0 < min(len(ref_xy), len(m1)))
    back = np.full(len(m0), -1, np.int64)
    back[known] = m1[m0[known]]
    idx = np.nonzero(known & (back == np.arange(len(m0))) & (conf > threshold))[0]
    h, w = ref_mask.shape
    xy = np.round(np.asarray(ref_xy, np.float64)[m0[idx]]).astype(np.int64).reshape(-1, 2)
    on_object = ref_mask[np.clip(xy[:, 1], 0, h - 1), np.clip(xy[:, 0], 0, w - 1)]
    return PairMatches(obs_index=idx, confidence=conf[idx], on_object=on_object.astype(bool))


def object_points(pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> np.ndarray:
    """Observation keypoints matched, in any pair, to a reference keypoint on the object (each once)."""
    idx = [p.obs_index[p.on_object] for p in pairs]
    idx = np.unique(np.concatenate(idx)) if idx else np.zeros(0, np.int64)
    return np.asarray(obs_xy, np.float32).reshape(-1, 2)[idx]


# ---------------------------------------------------------------------------- verdicts
def confidence_sum(pair: PairMatches) -> float:
    """PIN's SuperGlue evidence of one reference: the confidences of its valid matches, summed."""
    return float(pair.confidence.sum())


def on_object_count(pair: PairMatches) -> float:
    """The evidence of one reference: its valid matches whose reference keypoint lies on the object."""
    return float(pair.on_object.sum())


def combined_verdict(pairs: Sequence[PairMatches], obs_xy: np.ndarray, combine: str,
                     evidence: Callable[[PairMatches], float]) -> MatchResult:
    """Score = each reference's ``evidence`` summed over the references (``combine="max"``: the best one's);
    points = the observation keypoints matched to the object in any reference, each once, at the frame score."""
    if combine not in COMBINE:
        raise ValueError(f"combined_verdict: combine={combine!r}, choose one of {COMBINE}")
    per_reference = [evidence(p) for p in pairs]
    score = sum(per_reference) if combine == "sum" else max(per_reference, default=0.0)
    return MatchResult(score=float(score), points=object_points(pairs, obs_xy))


def count_verdict(pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult:
    """Score = number of distinct observation keypoints validly matched to the object in any reference."""
    points = object_points(pairs, obs_xy)
    return MatchResult(score=float(len(points)), points=points)


# ---------------------------------------------------------------------------- pairing rules of the graph matchers
def normalize_keypoints(xy: torch.Tensor, height: int, width: int, scale: float) -> torch.Tensor:
    """Keypoints centred on their own image and divided by ``scale`` x its longer side.

    SuperGlue uses 0.7, LightGlue 0.5; each image of a pair is normalised with its own size,
    as the original codes do for two images of different sizes.
    """
    return (xy - xy.new_tensor([width / 2, height / 2])) / (scale * max(height, width))


def mutual_matches(log_p: torch.Tensor, threshold: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Matches of a pair's ``(m, n)`` log assignment (no dustbins): mutual best, confidence above ``threshold``.

    The rule of both SuperGlue and LightGlue. Returns ``(matches0 (m,), matches1 (n,), confidence0 (m,))``,
    -1 for no match; ``confidence0`` is the exponentiated log assignment of each mutual match (0 otherwise).
    """
    m, n = log_p.shape
    if not m or not n:
        return log_p.new_full((m,), -1, dtype=torch.long), log_p.new_full((n,), -1, dtype=torch.long), \
            log_p.new_zeros(m)
    best0, best1 = log_p.max(1), log_p.max(0)
    mutual0 = best1.indices[best0.indices] == torch.arange(m, device=log_p.device)
    mutual1 = best0.indices[best1.indices] == torch.arange(n, device=log_p.device)
    conf0 = torch.where(mutual0, best0.values.exp(), log_p.new_zeros(()))
    valid0 = mutual0 & (conf0 > threshold)
    valid1 = mutual1 & valid0[best1.indices]
    return torch.where(valid0, best0.indices, -1), torch.where(valid1, best1.indices, -1), conf0


# ---------------------------------------------------------------------------- config and the reference loop
@dataclass
class KeypointConfig(CropConfig):
    """What every keypoint matcher is configured by; subclasses change the defaults to their method's."""

    crops: str = crops_field("whole")  # PIN matches the whole frame; "pin" also works (max over square crops)
    weights: str | None = weights_field()
    max_keypoints: int = field(default=1024, metadata={"help": "keypoints kept per image (the strongest)"})
    match_threshold: float = field(default=0.2, metadata={"help": "valid matches: mutual and confidence above"})


@dataclass
class CombineConfig(KeypointConfig):
    """A keypoint matcher whose score adds up (or picks the best of) the references' evidence."""

    combine: str = field(default="sum", metadata={"help": f"score over the six references: one of {COMBINE}"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.combine not in COMBINE:
            raise ConfigError(f"combine={self.combine!r}: choose one of {COMBINE}")


class ReferenceKeypointMatcher(CropMatcher):
    """Keypoints of the frame matched to PIN's six prepared references, one pair at a time (see module doc).

    Subclasses load their models, find keypoints in same-size images, pair one observation with one
    reference and turn the valid matches of all pairs into a verdict.
    """

    Config: ClassVar[type[MatcherConfig]] = KeypointConfig
    color_references: ClassVar[bool] = False  # grayscale references, as SuperPoint reads them

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self._refs: list[tuple[Keypoints, np.ndarray, np.ndarray]] = []  # keypoints, their xy as numpy, mask

    @property
    def threshold(self) -> float:
        return self.cfg.match_threshold

    @abstractmethod
    def _load(self) -> None:
        """Load the models, once: ``prepare`` calls it, never the constructor."""

    @abstractmethod
    def _extract(self, images: list[np.ndarray]) -> list[Keypoints]:
        """Keypoints of same-size images (the prepared references, or one frame)."""

    @abstractmethod
    def _pair(self, obs: Keypoints, ref: Keypoints) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(matches0 (m,), matches1 (n,), confidence0 (m,)) of one pair, -1 = no match."""

    @abstractmethod
    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult: ...

    def _observation(self, crop: np.ndarray) -> tuple[np.ndarray, float]:
        """The image the frame's keypoints are found in, and the factor from its pixels back to the crop's."""
        return crop, 1.0

    @torch.inference_mode()
    def _prepare(self, target: Target) -> None:
        self._load()
        refs = prepare_references(target.views, color=self.color_references)
        found = self._extract([r.image for r in refs])
        # a reference without keypoints can match nothing
        self._refs = [(k, k.xy.cpu().numpy(), r.mask) for k, r in zip(found, refs) if len(k.xy)]

    @torch.inference_mode()
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        return [self._match_one(crop) for crop in crops]

    def _match_one(self, crop: np.ndarray) -> MatchResult:
        image, back = self._observation(crop)
        obs = self._extract([image])[0]
        if not len(obs.xy) or not self._refs:
            return MatchResult(score=0.0)
        pairs = [valid_matches(*self._pair(obs, ref), ref_xy, mask, self.threshold)
                 for ref, ref_xy, mask in self._refs]
        # keypoints of the (possibly shrunk) image, back in crop pixels (kept inside it)
        xy = obs.xy.cpu().numpy().astype(np.float64) * back
        xy = np.clip(xy, 0, np.array([crop.shape[1], crop.shape[0]], np.float64) - 1e-3)
        return self._verdict(pairs, xy)

