"""Keypoint matchers: SuperGlue (PIN's baseline), LightGlue, and an IEVE-style composite of the two kinds.

SuperPoint finds keypoints in the observation and in PIN's six prepared references (three
views, each at two scales on a white 360x360 canvas); a graph matcher pairs them. The
references' keypoints are computed once per target, because the transformers models'
``forward`` only pairs images of one size and would run SuperPoint on every reference
again for every frame. SuperGlue's and LightGlue's matching stages are run here from the
models' public modules, one pair at a time on its real keypoints (``superglue_pair``,
``lightglue_pair``), and SuperPoint's border and top-k rules are applied here (``detect``).
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
from pin_match.matchers.hf_load import load_pretrained

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


def border_and_top_k(xy: torch.Tensor, scores: torch.Tensor, border: int, height: int, width: int,
                     max_keypoints: int) -> torch.Tensor:
    """Indices of the keypoints SuperPoint keeps: ``border`` px from every edge of the score map, then the strongest.

    magicleap's SuperPoint removes the border band of the full-resolution score map
    (``height x width``, the image floored to a multiple of 8) and only then cuts to the top
    ``max_keypoints``. transformers (5.23, ``SuperPointInterestPointDecoder._extract_keypoints``)
    passes 8 x the full-resolution size as the bound, so its bottom and right bands survive and
    push other keypoints out of the top-k. ``detect`` therefore asks it for every keypoint and
    applies both rules here. On keypoints that already lack the band (a fixed transformers)
    the border test keeps everything, so the result does not depend on which one is installed.
    Ties at the cut are broken by ``torch.topk`` on the row-major order, as magicleap's code does.
    """
    x, y = xy[:, 0], xy[:, 1]
    inside = (y >= border) & (y < height - border) & (x >= border) & (x < width - border)
    kept = torch.nonzero(inside).flatten()
    if 0 <= max_keypoints < len(kept):
        kept = kept[torch.topk(scores[kept], max_keypoints, dim=0).indices]
    return kept


def detect(detector: torch.nn.Module, grays: Sequence[np.ndarray], device: str, max_keypoints: int) -> list[Keypoints]:
    """Run SuperPoint on same-size grayscale uint8 images (one batch), with magicleap's border and top-k rules.

    The detector must be built with ``max_keypoints=-1`` (``SuperPointGlueMatcher._configure_detector``): it returns
    every thresholded NMS maximum, and ``border_and_top_k`` keeps SuperPoint's. Descriptors are sampled per
    keypoint, so selecting rows afterwards gives the same descriptors as sampling only the kept keypoints.
    """
    h, w = grays[0].shape
    x = torch.from_numpy(np.stack(grays)).to(device=device, dtype=torch.float32)[:, None] / 255.0
    out = detector(x)
    size = torch.tensor([w, h], dtype=torch.float32, device=device)
    border = detector.config.border_removal_distance
    found = []
    for kp, sc, de, mask in zip(out.keypoints, out.scores, out.descriptors, out.mask):
        n = int(mask.sum())  # SuperPoint pads after the real keypoints
        xy = (kp[:n] * size).round()
        kept = border_and_top_k(xy, sc[:n], border, h // 8 * 8, w // 8 * 8, max_keypoints)
        found.append(Keypoints(xy=xy[kept], scores=sc[:n][kept], descriptors=de[:n][kept], height=h, width=w))
    return found


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


# ---------------------------------------------------------------------------- pair matching stages
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


# LightGlue (Lindenberger et al., ICCV 2023; cvg/LightGlue's lightglue.py) for one pair, from the transformers
# model's layers. transformers' own pair matching (``_match_image_pair``) is private and pads every pair of a
# batch to one keypoint count; its attention modules reshape keys with the queries' length, so they cannot take
# two images with different counts either. The attention below reads their projections.
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


class SuperPointGlueMatcher(CropMatcher):
    """transformers' SuperPoint keypoints of the grayscale frame matched against PIN's six prepared references.

    Subclasses say how to load their transformers model (SuperPoint + a graph matcher), match one
    observation-reference pair and turn the valid matches into a verdict.
    """

    weights_spec: ClassVar[WeightsSpec]

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self._model: torch.nn.Module | None = None
        self._refs: list[tuple[Keypoints, np.ndarray, np.ndarray]] = []  # keypoints, their xy as numpy, mask

    @abstractmethod
    def _load(self, source: str) -> torch.nn.Module: ...

    @abstractmethod
    def _pair(self, obs: Keypoints, ref: Keypoints) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(matches0 (m,), matches1 (n,), confidence0 (m,)) of one pair, -1 = no match."""

    @abstractmethod
    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult: ...

    def _configure_detector(self, detector_config: Any) -> None:
        """SuperPoint reads these when it is built, so they go into the config before loading.

        It returns every keypoint (``max_keypoints=-1``): the border and top-k rules are ``detect``'s.
        """
        detector_config.nms_radius = self.cfg.nms_radius
        detector_config.keypoint_threshold = self.cfg.keypoint_threshold
        detector_config.max_keypoints = -1

    def _detect(self, grays: Sequence[np.ndarray]) -> list[Keypoints]:
        return detect(self._model.keypoint_detector, grays, self.cfg.device, self.cfg.max_keypoints)

    @torch.inference_mode()
    def _prepare(self, target: Target) -> None:
        if self._model is None:
            model = load_pretrained(self.weights_spec, self.cfg.weights, f"matcher {self.display_name}", self._load)
            self._model = model.to(self.cfg.device).eval()
        refs = prepare_references(target.views)
        found = self._detect([r.image for r in refs])
        # a reference without keypoints can match nothing
        self._refs = [(k, k.xy.cpu().numpy(), r.mask) for k, r in zip(found, refs) if len(k.xy)]

    @torch.inference_mode()
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        return [self._match_one(crop) for crop in crops]

    def _match_one(self, crop: np.ndarray) -> MatchResult:
        obs = self._detect([cv2.cvtColor(crop, cv2.COLOR_RGB2GRAY)])[0]
        if not len(obs.xy) or not self._refs:
            return MatchResult(score=0.0)
        pairs = []
        for ref, ref_xy, mask in self._refs:
            m0, m1, conf = (t.cpu().numpy() for t in self._pair(obs, ref))
            pairs.append(valid_matches(m0, m1, conf.astype(np.float32), ref_xy, mask, self.cfg.match_threshold))
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
class SuperGlueMatcher(SuperPointGlueMatcher):
    """PIN's SuperGlue baseline: score = sum of the confidences of the valid matches over the six references.

    Each observation-reference pair is matched on its own keypoints (``superglue_pair``), as
    magicleap's SuperGlue does, so the optimal transport's marginals are the pair's real counts.
    """

    Config = SuperGlueMatcherConfig
    modality = Modality.VISUAL
    default_sigma = 8.0
    weights_spec = SUPERGLUE_WEIGHTS
    paper = "Sarlin et al., SuperGlue: Learning Feature Matching with Graph Neural Networks, CVPR 2020"
    # 2: optimal transport per pair with its real keypoint counts (was: padded batch)
    # 3: SuperPoint's 4 px border removed on every edge before the top-k cut (transformers kept the bottom / right)
    version = 3

    def _load(self, source: str) -> torch.nn.Module:
        from transformers import SuperGlueConfig, SuperGlueForKeypointMatching

        config = SuperGlueConfig.from_pretrained(source)
        self._configure_detector(config.keypoint_detector_config)
        return SuperGlueForKeypointMatching.from_pretrained(source, config=config)

    def _pair(self, obs: Keypoints, ref: Keypoints) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return superglue_pair(self._model, obs, ref, self.cfg.sinkhorn_iterations, self.cfg.match_threshold)

    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult:
        return superglue_verdict(pairs, obs_xy, self.cfg.combine)


@dataclass
class LightGlueMatcherConfig(KeypointConfig):
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
    # 2: SuperPoint's border removed on every edge before the top-k cut; each pair matched alone (``lightglue_pair``,
    #    no padding) instead of transformers' private batched ``_match_image_pair``
    version = 2

    def _load(self, source: str) -> torch.nn.Module:
        from transformers import LightGlueConfig, LightGlueForKeypointMatching

        config = LightGlueConfig.from_pretrained(source)
        self._configure_detector(config.keypoint_detector_config)
        return LightGlueForKeypointMatching.from_pretrained(source, config=config)

    def _pair(self, obs: Keypoints, ref: Keypoints) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return lightglue_pair(self._model, obs, ref, self.cfg.match_threshold)

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
