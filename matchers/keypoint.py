"""Keypoint matchers: SuperGlue (PIN's baseline), LightGlue, and an IEVE-style composite of the two kinds.

SuperPoint finds keypoints in the observation and in PIN's six prepared references (three
views, each at two scales on a white 360x360 canvas); a graph matcher pairs them. The
references' keypoints are computed once per target, because the transformers models'
``forward`` only pairs images of one size and would run SuperPoint on every reference
again for every frame. SuperGlue's matching stage is run here from the model's public
modules, one pair at a time on its real keypoints (see ``superglue_pair``).
"""

from __future__ import annotations

import dataclasses
import math
from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import cv2
import numpy as np
import torch

from matchers.hf_load import load_pretrained
from pin_match.contract import (
    ConfigError,
    CropConfig,
    CropMatcher,
    Matcher,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    Target,
    WeightsError,
    WeightsSpec,
    create_matcher,
    crops_field,
    get_matcher_class,
    register_matcher,
    weights_field,
)

SUPERGLUE_WEIGHTS = WeightsSpec("magic-leap-community/superglue_indoor",
                                license="Magic Leap non-commercial research license (SuperPoint and SuperGlue)")
LIGHTGLUE_WEIGHTS = WeightsSpec("ETH-CVG/lightglue_superpoint",
                                license="Apache-2.0 (LightGlue); SuperPoint's Magic Leap non-commercial license")

REFERENCE_PAD = 30        # pixels of background kept around the object's mask
REFERENCE_CANVAS = 360    # side of the square canvas every prepared reference is drawn on
REFERENCE_SIDES = (360, 180)  # each view at two scales, so near and far objects both match


# ---------------------------------------------------------------------------- reference preparation
def square_box(alpha: np.ndarray, pad: int) -> tuple[int, int, int, int]:
    """The square ``(x0, y0, x1, y1)`` (x1, y1 exclusive) centred on the mask's bounding box.

    Its side is the box's longer side plus ``pad`` on both ends; it may stick out of the image.
    """
    ys, xs = np.nonzero(alpha)
    if not len(xs):
        raise ValueError("square_box: the alpha mask is empty")
    bx0, by0, bx1, by1 = int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1
    side = max(bx1 - bx0, by1 - by0) + 2 * pad
    x0 = bx0 - (side - (bx1 - bx0)) // 2
    y0 = by0 - (side - (by1 - by0)) // 2
    return x0, y0, x0 + side, y0 + side


def take_box(image: np.ndarray, box: tuple[int, int, int, int], fill: Any) -> np.ndarray:
    """The pixels of ``box``; where it leaves the image they are ``fill`` (the background colour)."""
    x0, y0, x1, y1 = box
    out = np.full((y1 - y0, x1 - x0) + image.shape[2:], fill, image.dtype)
    h, w = image.shape[:2]
    sx0, sy0, sx1, sy1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    if sx1 > sx0 and sy1 > sy0:
        out[sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = image[sy0:sy1, sx0:sx1]
    return out


@dataclass(frozen=True)
class ReferenceImage:
    image: np.ndarray  # canvas x canvas uint8 (grayscale, or x 3 RGB when prepared in colour), white background
    mask: np.ndarray   # canvas x canvas bool, the object's pixels


def prepare_references(views: Sequence[np.ndarray], pad: int = REFERENCE_PAD, canvas: int = REFERENCE_CANVAS,
                       sides: Sequence[int] = REFERENCE_SIDES, *, color: bool = False) -> list[ReferenceImage]:
    """PIN's SuperGlue references: white background, square crop around the mask, each view at every side.

    The smaller scales are centred on the canvas. Order: view-major (view 0 at every side, then view 1...).
    Grayscale as SuperPoint reads them; ``color=True`` keeps RGB for detectors trained on colour (DISK, ALIKED).
    """
    out = []
    for view in views:
        alpha = view[..., 3:4].astype(np.float32) / 255.0
        rgb = np.round(view[..., :3] * alpha + 255.0 * (1.0 - alpha)).astype(np.uint8)
        box = square_box(view[..., 3] > 0, pad)
        crop = take_box(rgb, box, 255)
        if not color:
            crop = cv2.cvtColor(crop, cv2.COLOR_RGB2GRAY)
        mask = take_box((view[..., 3] > 0).astype(np.uint8), box, 0)
        for side in sides:
            off = (canvas - side) // 2
            image = np.full((canvas, canvas, *crop.shape[2:]), 255, np.uint8)
            m = np.zeros((canvas, canvas), bool)
            image[off:off + side, off:off + side] = cv2.resize(crop, (side, side), interpolation=cv2.INTER_AREA)
            m[off:off + side, off:off + side] = cv2.resize(mask, (side, side), interpolation=cv2.INTER_NEAREST) > 0
            out.append(ReferenceImage(image=image, mask=m))
    return out


# ---------------------------------------------------------------------------- keypoints and pairing
@dataclass
class Keypoints:
    """SuperPoint's output for one image, in that image's pixels."""

    xy: torch.Tensor           # (N, 2) x, y
    scores: torch.Tensor       # (N,)
    descriptors: torch.Tensor  # (N, D)
    height: int
    width: int


def detect(detector: torch.nn.Module, grays: Sequence[np.ndarray], device: str) -> list[Keypoints]:
    """Run SuperPoint on same-size grayscale uint8 images (one batch)."""
    h, w = grays[0].shape
    x = torch.from_numpy(np.stack(grays)).to(device=device, dtype=torch.float32)[:, None] / 255.0
    out = detector(x)
    size = torch.tensor([w, h], dtype=torch.float32, device=device)
    found = []
    for kp, sc, de, mask in zip(out.keypoints, out.scores, out.descriptors, out.mask):
        n = int(mask.sum())  # SuperPoint pads after the real keypoints
        found.append(Keypoints(xy=(kp[:n] * size).round(), scores=sc[:n], descriptors=de[:n], height=h, width=w))
    return found


def to_frame_of(xy: torch.Tensor, src_hw: tuple[int, int], dst_hw: tuple[int, int]) -> torch.Tensor:
    """Move keypoints of a ``src`` image so the matcher's normalisation for a ``dst`` image is their own.

    SuperGlue and LightGlue normalise a pair with one image size, ``(xy - size / 2) / (c * max(size))``;
    this affine map makes that equal to normalising the reference with its own size, as the
    original SuperGlue code does for two images of different sizes.
    """
    (sh, sw), (dh, dw) = src_hw, dst_hw
    src_centre = xy.new_tensor([sw / 2, sh / 2])
    dst_centre = xy.new_tensor([dw / 2, dh / 2])
    return (xy - src_centre) * (max(dh, dw) / max(sh, sw)) + dst_centre


@dataclass
class PairBatch:
    """One observation against R references, padded to a common keypoint count, as the models take it."""

    keypoints: torch.Tensor    # (R, 2, N, 2), index 0 = observation, 1 = reference
    descriptors: torch.Tensor  # (R, 2, N, D)
    scores: torch.Tensor       # (R, 2, N)
    mask: torch.Tensor         # (R, 2, N) int, 1 = a real keypoint


def pair_batch(obs: Keypoints, refs: Sequence[Keypoints]) -> PairBatch:
    n = max(len(k.xy) for k in (obs, *refs))
    r, d = len(refs), obs.descriptors.shape[1]
    device = obs.xy.device
    batch = PairBatch(torch.zeros(r, 2, n, 2, device=device), torch.zeros(r, 2, n, d, device=device),
                      torch.zeros(r, 2, n, device=device), torch.zeros(r, 2, n, dtype=torch.int, device=device))
    for i, ref in enumerate(refs):
        ref_xy = to_frame_of(ref.xy, (ref.height, ref.width), (obs.height, obs.width))
        for k, (xy, kps) in enumerate(((obs.xy, obs), (ref_xy, ref))):
            m = len(xy)
            batch.keypoints[i, k, :m] = xy
            batch.descriptors[i, k, :m] = kps.descriptors
            batch.scores[i, k, :m] = kps.scores
            batch.mask[i, k, :m] = 1
    return batch


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


SUPERGLUE_COMBINE = ("sum", "max")


def superglue_verdict(pairs: Sequence[PairMatches], obs_xy: np.ndarray, combine: str = "sum") -> MatchResult:
    """Score = the confidences of the valid matches summed per reference, then summed (or, with
    ``combine="max"``, the best reference's sum); points = the matches on the object, all references."""
    per_reference = [float(p.confidence.sum()) for p in pairs]
    if combine not in SUPERGLUE_COMBINE:
        raise ValueError(f"superglue_verdict: combine={combine!r}, choose one of {SUPERGLUE_COMBINE}")
    score = sum(per_reference) if combine == "sum" else max(per_reference, default=0.0)
    return MatchResult(score=float(score), points=object_points(pairs, obs_xy))


# ---------------------------------------------------------------------------- SuperGlue's matching stage
def normalize_keypoints(xy: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """SuperGlue's keypoint normalisation: centred on the image, divided by 0.7 x its longer side."""
    return (xy - xy.new_tensor([width / 2, height / 2])) / (0.7 * max(height, width))


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


def superglue_pair(model: torch.nn.Module, xy: tuple[torch.Tensor, torch.Tensor],
                   descriptors: tuple[torch.Tensor, torch.Tensor], scores: tuple[torch.Tensor, torch.Tensor],
                   iterations: int, threshold: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """SuperGlue on one pair of unpadded keypoint sets (already normalised), with the model's public modules.

    Keypoint encoder, self / cross attention layers updating both sets at once, final
    projection, scores / sqrt(D), optimal transport on the real m x n block, then matches
    that are mutual best and whose confidence exceeds ``threshold``. Returns
    ``(matches0 (m,), matches1 (n,), confidence0 (m,), confidence1 (n,))``, -1 for no match.
    """
    desc = [d[None] + model.keypoint_encoder(k[None], s[None])[0] for d, k, s in zip(descriptors, xy, scores)]
    for layer, kind in zip(model.gnn.layers, model.gnn.layers_types):
        sources = desc[::-1] if kind == "cross" else desc
        desc = [d + layer(d, encoder_hidden_states=src)[0] for d, src in zip(desc, sources)]
    proj0, proj1 = (model.final_projection(d)[0] for d in desc)
    log_p = log_optimal_transport(proj0 @ proj1.T / proj0.shape[-1] ** 0.5, model.bin_score, iterations)[:-1, :-1]
    best0, best1 = log_p.max(1), log_p.max(0)
    mutual0 = best1.indices[best0.indices] == torch.arange(len(best0.indices), device=log_p.device)
    mutual1 = best0.indices[best1.indices] == torch.arange(len(best1.indices), device=log_p.device)
    conf0 = torch.where(mutual0, best0.values.exp(), log_p.new_zeros(()))
    conf1 = torch.where(mutual1, conf0[best1.indices], log_p.new_zeros(()))
    valid0 = mutual0 & (conf0 > threshold)
    valid1 = mutual1 & valid0[best1.indices]
    return (torch.where(valid0, best0.indices, -1), torch.where(valid1, best1.indices, -1), conf0, conf1)


def count_verdict(pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult:
    """Score = number of distinct observation keypoints validly matched to the object in any reference."""
    points = object_points(pairs, obs_xy)
    return MatchResult(score=float(len(points)), points=points)


# ---------------------------------------------------------------------------- matchers
@dataclass
class KeypointConfig(CropConfig):
    crops: str = crops_field("whole")  # PIN matches the whole frame; "pin" also works (max over square crops)
    weights: str | None = weights_field()
    nms_radius: int = 4
    keypoint_threshold: float = 0.005
    max_keypoints: int = 1024
    match_threshold: float = field(default=0.2, metadata={"help": "valid matches: mutual and confidence above"})


class GlueMatcher(CropMatcher):
    """SuperPoint keypoints of the grayscale frame matched against PIN's six prepared references.

    Subclasses say how to load their model, run its pair-matching stage and turn the valid matches into a verdict.
    """

    weights_spec: ClassVar[WeightsSpec]

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self._model: torch.nn.Module | None = None
        self._refs: list[tuple[Keypoints, np.ndarray, np.ndarray]] = []  # keypoints, their xy as numpy, mask

    @abstractmethod
    def _load(self, source: str) -> torch.nn.Module: ...

    @abstractmethod
    def _glue(self, pairs: PairBatch, height: int, width: int) -> tuple[torch.Tensor, torch.Tensor]:
        """(matches, confidences), each (R, 2, N)."""

    @abstractmethod
    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult: ...

    def _configure_detector(self, detector_config: Any) -> None:
        """SuperPoint reads these when it is built, so they go into the config before loading."""
        detector_config.nms_radius = self.cfg.nms_radius
        detector_config.keypoint_threshold = self.cfg.keypoint_threshold
        detector_config.max_keypoints = self.cfg.max_keypoints

    @torch.inference_mode()
    def _prepare(self, target: Target) -> None:
        if self._model is None:
            model = load_pretrained(self.weights_spec, self.cfg.weights, f"matcher {self.display_name}", self._load)
            self._model = model.to(self.cfg.device).eval()
        refs = prepare_references(target.views)
        found = detect(self._model.keypoint_detector, [r.image for r in refs], self.cfg.device)
        # a reference without keypoints can match nothing; leaving it out keeps the pair batch well-formed
        self._refs = [(k, k.xy.cpu().numpy(), r.mask) for k, r in zip(found, refs) if len(k.xy)]

    @torch.inference_mode()
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        return [self._match_one(crop) for crop in crops]

    def _match_one(self, crop: np.ndarray) -> MatchResult:
        obs = detect(self._model.keypoint_detector, [cv2.cvtColor(crop, cv2.COLOR_RGB2GRAY)], self.cfg.device)[0]
        if not len(obs.xy) or not self._refs:
            return MatchResult(score=0.0)
        matches, conf = self._glue(pair_batch(obs, [k for k, _, _ in self._refs]), obs.height, obs.width)
        matches, conf = matches.cpu().numpy(), conf.float().cpu().numpy()
        n = len(obs.xy)
        pairs = [valid_matches(matches[i, 0, :n], matches[i, 1, :len(xy)], conf[i, 0, :n], xy, mask,
                               self.cfg.match_threshold)
                 for i, (_, xy, mask) in enumerate(self._refs)]
        return self._verdict(pairs, obs.xy.cpu().numpy())


@dataclass
class SuperGlueMatcherConfig(KeypointConfig):
    sinkhorn_iterations: int = 20
    combine: str = field(default="sum", metadata={
        "help": "score over the six references: sum (PIN's 'sum of confidences', as read here) or max"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.combine not in SUPERGLUE_COMBINE:
            raise ConfigError(f"combine={self.combine!r}: choose one of {SUPERGLUE_COMBINE}")
        if self.sinkhorn_iterations < 0:
            raise ConfigError(f"sinkhorn_iterations={self.sinkhorn_iterations}: must be >= 0")


@register_matcher("superglue")
class SuperGlueMatcher(GlueMatcher):
    """PIN's SuperGlue baseline: score = sum of the confidences of the valid matches over the six references.

    Each observation-reference pair is matched on its own keypoints (``superglue_pair``), as
    magicleap's SuperGlue does, so the optimal transport's marginals are the pair's real counts.
    """

    Config = SuperGlueMatcherConfig
    modality = Modality.VISUAL
    default_sigma = 8.0
    weights_spec = SUPERGLUE_WEIGHTS
    paper = "Sarlin et al., SuperGlue: Learning Feature Matching with Graph Neural Networks, CVPR 2020"
    version = 2  # 2: optimal transport per pair with its real keypoint counts (was: padded batch)

    def _load(self, source: str) -> torch.nn.Module:
        from transformers import SuperGlueConfig, SuperGlueForKeypointMatching

        config = SuperGlueConfig.from_pretrained(source)
        self._configure_detector(config.keypoint_detector_config)
        return SuperGlueForKeypointMatching.from_pretrained(source, config=config)

    def _glue(self, pairs: PairBatch, height: int, width: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Each pair unpadded: the references' keypoints were moved into the observation's frame, so one
        normalisation with the observation's size is each image's own (``to_frame_of``)."""
        r, _, n = pairs.mask.shape
        matches = torch.full((r, 2, n), -1, dtype=torch.long, device=pairs.keypoints.device)
        conf = torch.zeros((r, 2, n), device=pairs.keypoints.device)
        xy = normalize_keypoints(pairs.keypoints, height, width)
        for i in range(r):
            m0, m1 = (int(c) for c in pairs.mask[i].sum(1))
            out = superglue_pair(self._model, (xy[i, 0, :m0], xy[i, 1, :m1]),
                                 (pairs.descriptors[i, 0, :m0], pairs.descriptors[i, 1, :m1]),
                                 (pairs.scores[i, 0, :m0], pairs.scores[i, 1, :m1]),
                                 self.cfg.sinkhorn_iterations, self.cfg.match_threshold)
            matches[i, 0, :m0], matches[i, 1, :m1], conf[i, 0, :m0], conf[i, 1, :m1] = out
        return matches, conf

    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult:
        return superglue_verdict(pairs, obs_xy, self.cfg.combine)


@dataclass
class LightGlueMatcherConfig(KeypointConfig):
    match_threshold: float = field(default=0.1, metadata={"help": "LightGlue's own filter threshold"})


@register_matcher("lightglue")
class LightGlueMatcher(GlueMatcher):
    """SuperPoint + LightGlue against PIN's six references; score = number of observation keypoints matched to
    the object (distinct keypoints, so one seen in several references counts once)."""

    Config = LightGlueMatcherConfig
    modality = Modality.VISUAL
    default_sigma = 100.0  # IEVE's "confirmed" match count
    weights_spec = LIGHTGLUE_WEIGHTS
    paper = "Lindenberger et al., LightGlue: Local Feature Matching at Light Speed, ICCV 2023"

    def _load(self, source: str) -> torch.nn.Module:
        from transformers import LightGlueConfig, LightGlueForKeypointMatching

        config = LightGlueConfig.from_pretrained(source)
        config.filter_threshold = 0.0  # the threshold is applied once, in valid_matches
        self._configure_detector(config.keypoint_detector_config)
        return LightGlueForKeypointMatching.from_pretrained(source, config=config)

    def _glue(self, pairs: PairBatch, height: int, width: int) -> tuple[torch.Tensor, torch.Tensor]:
        matches, conf, *_ = self._model._match_image_pair(pairs.keypoints, pairs.descriptors, height, width,
                                                          mask=pairs.mask)
        r = pairs.keypoints.shape[0]
        return matches.reshape(r, 2, -1), conf.reshape(r, 2, -1)

    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult:
        return count_verdict(pairs, obs_xy)


# ---------------------------------------------------------------------------- IEVE-style composite
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
    gate_weights: str | None = field(default=None, metadata={"help": "weights= of the gate"})
    gate_sigma: float = field(default=0.2, metadata={"help": "the gate's own box threshold (IEVE's detector)"})
    keypoints: str = field(default="disk-lightglue", metadata={
        "help": "registered matcher giving matched keypoints (IEVE: DISK + LightGlue)"})
    keypoints_weights: str | None = field(default=None, metadata={"help": "weights= of the keypoint matcher"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if "ieve" in (self.gate, self.keypoints):
            raise ConfigError("matcher ieve cannot use itself as a part")


@register_matcher("ieve")
class IeveMatcher(Matcher):
    """IEVE-style: a category detector opens a box, keypoint matches inside it are counted.

    Both parts are registered matchers built by name. A gate whose config has a ``query`` field
    (OWL) is switched to ``query="category"``, asked as CoW's "a photo of a {}.", and so reads
    the category label, which is why this matcher is of the category modality. The gate threshold
    is internal to the design (IEVE's detector has one); the final score, the match count, is
    still left un-thresholded.
    Each part keeps its own crop policy.
    """

    Config = IeveConfig
    modality = Modality.CATEGORY
    default_sigma = 100.0  # IEVE: > 100 matches confirm the goal (60: near it)
    paper = ("Lei et al., Instance-aware Exploration-Verification-Exploitation for Instance ImageGoal Navigation, "
             "CVPR 2024")

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        gate_options: dict[str, Any] = {}
        gate_fields = {f.name for f in dataclasses.fields(get_matcher_class(self.cfg.gate).Config)}
        if "query" in gate_fields:
            gate_options["query"] = "category"
        if "prompt" in gate_fields:  # a category word alone is a poor query: CoW and PIN ask "a photo of a {}."
            gate_options["prompt"] = "a-photo-of"
        if self.cfg.gate_weights is not None:
            gate_options["weights"] = self.cfg.gate_weights
        keypoint_options = {"weights": self.cfg.keypoints_weights} if self.cfg.keypoints_weights is not None else {}
        self.gate = create_matcher(self.cfg.gate, **gate_options)
        self.keypoints = create_matcher(self.cfg.keypoints, **keypoint_options)

    def parts(self) -> dict[str, Matcher]:
        return {"gate": self.gate, "keypoints": self.keypoints}

    def _prepare(self, target: Target) -> None:
        # the full target: a category-modality gate gets the label, any other gate strips it itself
        for part, option in ((self.gate, "gate_weights"), (self.keypoints, "keypoints_weights")):
            try:
                part.prepare(target)
            except WeightsError as exc:
                raise WeightsError(f"matcher ieve, part {part.display_name!r} (set {option}=): {exc}") from exc

    def _match_batch(self, images: list[np.ndarray]) -> list[MatchResult]:
        gates = self.gate.match_batch(images)
        keypoints = self.keypoints.match_batch(images)
        return [gated_count(k.points, g.boxes, g.box_scores, self.cfg.gate_sigma, self.cfg.gate)
                for g, k in zip(gates, keypoints)]
