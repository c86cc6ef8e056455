"""``verify``: locate with a patch map, zoom on each candidate, re-identify it, check its colour.

A prototype averaged over the reference's mask and compared with a frame's coarse cells keeps
what a category shares and loses what tells two instances apart: an object 60 px tall covers
two or three stride-32 cells, each half background. Instance detectors for unseen objects
(CNOS, NIDS-Net) instead propose a region first and then compare the region's own descriptor
with the references'. This matcher does that with the default ``effnet``:

1. **Locate**: the ``locate`` part's patch map (``effnet``: head at 448 px, PIN's crops) gives
   up to ``candidates`` regions: a peak and the cells around it within ``region_drop`` of its
   score, grown to a box of the reference's aspect ratio (``matchers/common/candidates.py``).
2. **Zoom**: each box is cut from the frame at its own resolution and embedded again at
   ``zoom_size`` (the ``zoom`` part: the locate network at that input size); each reference view
   is cut to its mask's box and embedded the same way.
3. **Re-identify**, one signal each, any of which ``signals`` may leave out:
   ``proto`` the locate peak; ``margin`` the peak minus the best other candidate's;
   ``desc`` the cosine of the candidate's foreground-averaged descriptor with the best view's
   (foreground: the candidate's cells weighted by how much each resembles the references);
   ``cycle`` the mutual cell matches between candidate and view, weighted by cosine, over the
   view's cells (``effnet-parts``' mutual rule); ``color`` the Bhattacharyya overlap of the
   candidate's foreground HSV histogram with the references' masked one; ``keypoints``
   log(1 + valid on-object matches) of the ``keypoints`` part (``xfeat``) on the candidate crop,
   off by default (it helps printed packages only and costs 0.4x ``effnet`` a frame).
4. **Decide**: a logistic fusion of the signals read from a verifier file (fitted on a train
   split by ``pin_match.fitting.verifier.fit_verifier``; its content is hashed into the id; read and
   applied by ``matchers/common/verifier_file.py``),
   plus a bounded colour penalty (the file's ``gate``, the config's ``color_gate``): below the
   floor ``color_gate`` each unit of colour overlap (0-1) missing costs the fitted slope in logit, so
   the penalty subtracts at most slope x floor, reached at overlap 0, besides the linear colour
   weight's share (the hinge lets colour cost more below the floor than it adds above it: one
   linear colour weight cannot be large on recolours and small on toys at once). It lowers a
   candidate of the wrong colour by a bounded amount and is no veto: shape and texture terms
   larger than the bound still pass it (the carried file's numbers: docs/instance-matchers.md).
   The colour weight and the slope are never negative (fitted so, checked on reading), so a
   candidate's score never rises as its colour overlap falls, the other signals fixed. Each
   candidate's score is the fitted probability that it is the target, the frame's is its
   best candidate's. A probability means one thing on every frame-set, but its level carries only
   partly across sets (docs/instance-matchers.md).
5. **Point**: each candidate's first point is its most reference-like zoom cell (a box of 200 px
   squashed to ``zoom_size`` has cells of 25 px, a locate cell's size, so the best candidate is
   zoomed once more: a square of ``REFINE_SHARE`` of its box's longer side, at least
   ``REFINE_MIN_SIDE`` px, around that cell; there a cell's likeness plus ``REFINE_COLOUR`` x
   its pixels' mean colour back-projection (``color``'s ratio histogram of the references'
   colours over the frame's) picks the frame's first point) where the frame scores ``refine_floor`` or
   more: the point an agent walks to is a goal's, at or above sigma, and no score reads it; then the
   region's cells by locate score. Every point carries its candidate's score; the boxes come back with the
   result, each with the reference view its zoomed descriptor matched best
   (``MatchResult.box_views``). The points and views need the zoom: with
   none of its signals they are the region's cells and no views.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from pin_match.contract import (
    ConfigError,
    Frames,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    Target,
    WeightsError,
    crop_boxes,
    register_matcher,
    weights_field,
)
from pin_match.matchers.common.candidates import (
    Candidate,
    backprojection,
    bhattacharyya,
    cell_centre,
    color_histogram,
    locate,
    mask_aspect,
    square_around,
)
from pin_match.matchers.common.cell_parts import part_matches, reference_cells
from pin_match.matchers.common.composite import CompositeMatcher, part_cfg_field
from pin_match.matchers.common.fitted import FittedFileSpec
from pin_match.matchers.common.patch import PatchSimilarityMatcher, alpha_to_grid
from pin_match.matchers.common.verifier_file import DEFAULT_SIGNALS, SIGNALS, read_verifier, verdict
from pin_match.nn.prototypes import masked_mean

# a candidate crop is a few hundred pixels: half the keypoints of a whole frame cover it
KEYPOINT_DEFAULTS = {"crops": "whole", "max_keypoints": 256}
REFERENCE_PAD = 0.1  # a reference view is cut to its mask's box plus this share per side, as a candidate is padded
ZOOM_SIGNALS = ("desc", "cycle", "color")  # the signals that need the candidate embedded again
# chosen by cross-validation over MyVLM's train instances (docs/instance-matchers.md)
DEFAULT_COLOR_GATE = 0.8
# the best candidate's second zoom: measured on the scanned set's val target frames (docs/synthetic.md, by size)
REFINE_SHARE = 0.4
REFINE_MIN_SIDE = 64
REFINE_COLOUR = 0.5  # weight of the colour back-projection beside the likeness (0-1 each) in the second zoom
# the second zoom moves a point only an agent walking to a goal reads: a goal is a frame at or above sigma, and every
# sigma tuned for verify so far is 0.376 or more (docs/results.md), so frames under this floor keep the zoom's cell
DEFAULT_REFINE_FLOOR = 0.25
# what the signals' values depend on besides the config and the parts; the matcher's version also counts where the
# points go, which no signal reads: version 2 moved the points, so a verifier file fitted on version 1 still fits
SIGNALS_VERSION = 1


@dataclass
class VerifyConfig(MatcherConfig):
    """The parts, the signals and how candidates are drawn; ``weights`` is the verifier file."""

    weights: str | None = weights_field()
    locate: str = field(default="effnet", metadata={"help": "patch matcher whose map proposes candidates"})
    locate_cfg: dict[str, Any] = part_cfg_field("locate")
    zoom_size: int = field(default=256, metadata={"help": "input side at which candidates and views are embedded"})
    keypoints: str = field(default="xfeat", metadata={"help": "keypoint matcher run on each candidate crop"})
    keypoints_cfg: dict[str, Any] = part_cfg_field("keypoints")
    signals: tuple[str, ...] = field(default=DEFAULT_SIGNALS, metadata={
        "help": f"signals used, of {', '.join(SIGNALS)} (keypoints off by default: its cost)"})
    candidates: int = field(default=3, metadata={"help": "candidate regions verified per frame"})
    region_drop: float = field(default=0.1, metadata={"help": "a region holds the cells within this of its peak"})
    pad: float = field(default=0.15, metadata={"help": "share of a candidate box added on each side"})
    color_bins: tuple[int, ...] = field(default=(16, 4, 4), metadata={"help": "HSV histogram bins"})
    color_gate: float = field(default=DEFAULT_COLOR_GATE, metadata={
        "help": "colour overlap below which a candidate's logit drops in proportion to the shortfall (the verifier "
                "file's fitted gate slope; at most slope x color_gate, at overlap 0): a bounded colour penalty, "
                "not a veto; 0: none, colour only adds"})
    refine_floor: float = field(default=DEFAULT_REFINE_FLOOR, metadata={
        "help": "a frame scoring at least this gets its first point from a second, closer zoom; below it the point "
                "is the first zoom's cell (no score reads it; 0: every frame)"})

    def __post_init__(self) -> None:
        super().__post_init__()
        unknown = sorted(set(self.signals) - set(SIGNALS))
        if unknown or not self.signals or len(set(self.signals)) != len(self.signals):
            raise ConfigError(f"{type(self).__name__}: signals={self.signals!r}; name each of {', '.join(SIGNALS)} "
                              f"at most once, at least one")
        if self.candidates < 1 or self.zoom_size < 32 or self.zoom_size % 32:
            raise ConfigError(f"{type(self).__name__}: candidates must be >= 1 and zoom_size a multiple of 32")
        if len(self.color_bins) != 3 or min(self.color_bins) < 1:
            raise ConfigError(f"{type(self).__name__}: color_bins={self.color_bins!r}; three positive counts (H, S, V)")
        if not 0.0 <= self.pad <= 1.0 or self.region_drop < 0.0:
            raise ConfigError(f"{type(self).__name__}: pad must be in [0, 1] and region_drop >= 0")
        if not 0.0 <= self.refine_floor <= 1.0:
            raise ConfigError(f"{type(self).__name__}: refine_floor={self.refine_floor!r}; a score in [0, 1]")
        if not 0.0 <= self.color_gate < 1.0 or (self.color_gate and "color" not in self.signals):
            raise ConfigError(f"{type(self).__name__}: color_gate={self.color_gate!r}; in [0, 1), and above 0 only "
                              f"with the color signal")


@dataclass
class Reference:
    """The target as the zoomed signals see it: one descriptor per view, the views' mask cells, their colours."""

    descriptors: torch.Tensor  # (V, D) foreground averages, unit length: every candidate is compared with them
    cells: torch.Tensor        # (R, D) cells on the masks
    cell_views: torch.Tensor   # (R,) the view of each
    histogram: np.ndarray      # HSV histogram of every view's masked pixels
    aspect: float              # median width / height of the views' mask boxes


@register_matcher("verify")
class VerifyMatcher(CompositeMatcher):
    """Locate, zoom, re-identify, check colour; a fitted fusion decides (see module doc)."""

    Config = VerifyConfig
    modality = Modality.VISUAL
    weights_spec = FittedFileSpec(package="pin_match.matchers", package_file="verify_myvlm.json",
                                  distribution="pin-match",
                                  license="the verifier file's own: weights fitted by pin_match (MIT)")
    # PIN's first-match objective on MyVLM pasted's train instances (docs/instance-matchers.md); how far this
    # one sigma carries to other sets is measured there: tune it on frames like the agent's
    default_sigma = 0.658
    version = 3  # 2: the first point is the zoomed peak; boxes say which view matched; 3: the second zoom above a floor
    paper = ("detect, then re-identify (CNOS, Nguyen et al., ICCVW 2023; NIDS-Net, Lu et al., 2024) with "
             "cycle-consistent cell matches (Matcher, Liu et al., ICLR 2024) and a colour check (PInVerify, 2026)")

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        cfg = self.cfg
        self.locator = self._patch_part("locate", {})
        self.zoomer = self._patch_part("zoom", {"img_size": cfg.zoom_size, "crops": "whole"})
        # built (no weights load) even when its signal is off, so every signal set shares one signals_id and cache
        self.keypointer = self.add_part("keypoints", cfg.keypoints, cfg.keypoints_cfg, KEYPOINT_DEFAULTS)
        self.require_visual()
        self._reference: Reference | None = None

    def _patch_part(self, role: str, defaults: dict[str, Any]) -> PatchSimilarityMatcher:
        part = self.add_part(role, self.cfg.locate, self.cfg.locate_cfg, defaults)
        if not isinstance(part, PatchSimilarityMatcher):
            raise ConfigError(f"matcher {self.display_name}: locate={self.cfg.locate!r} has no patch map; choose a "
                              f"patch matcher such as effnet")
        return part

    @property
    def signals_id(self) -> str:
        """Hash of everything the signals' values depend on: not the verifier file, which signals are used, the
        colour gate (an ablation reads the same cached signals) or where the second zoom runs."""
        config = self.cfg.hashed_dict()
        for not_a_signal in ("weights", "signals", "color_gate", "refine_floor"):
            config.pop(not_a_signal, None)
        payload = dict(version=SIGNALS_VERSION, config=config, parts={r: p.id for r, p in self.parts().items()})
        return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:12]

    @cached_property
    def decision(self) -> dict[str, Any]:
        """The verifier file, refused unless it was fitted on exactly this matcher's signals."""
        path = self.weights_spec.resolve(self.cfg.weights, f"matcher {self.display_name}")
        spec = read_verifier(path)
        if set(spec["coefs"]) != set(self.cfg.signals) or spec.get("signals_id") != self.signals_id \
                or spec["gate"]["floor"] != self.cfg.color_gate:
            raise WeightsError(f"verifier file {path} was fitted on signals {sorted(spec['coefs'])} (signals id "
                               f"{spec.get('signals_id')}, colour gate {spec['gate']['floor']}), this matcher computes "
                               f"{sorted(self.cfg.signals)} (signals id {self.signals_id}, colour gate "
                               f"{self.cfg.color_gate}): refit it with pin_match.fitting.verifier.fit_verifier")
        return spec

    def weights_hint(self, role: str) -> str:
        return f"set {role}_cfg.weights=" if role != "zoom" else "set locate_cfg.weights="

    def roles_to_prepare(self) -> tuple[str, ...]:
        # the zoom part lends its network only (the references are cut and embedded below); keypoints when used
        return ("locate", "keypoints") if "keypoints" in self.cfg.signals else ("locate",)

    def _prepare(self, target: Target) -> None:
        super()._prepare(target)
        backbone = self.zoomer.backbone
        cuts, alphas, aspects = [], [], []
        for view in target.views:
            aspect, (x0, y0, x1, y1) = mask_aspect(view[..., 3])
            px, py = round(REFERENCE_PAD * (x1 - x0)), round(REFERENCE_PAD * (y1 - y0))
            cut = view[max(y0 - py, 0):y1 + py, max(x0 - px, 0):x1 + px]
            cuts.append(np.ascontiguousarray(cut[..., :3]))
            alphas.append(alpha_to_grid(cut[..., 3], backbone.grid).reshape(-1))
            aspects.append(aspect)
        feats = backbone.encode(cuts).patches
        cells, views = [], []
        for i, alpha in enumerate(alphas):
            keep = reference_cells(alpha, 0.5)
            cells.append(feats[i, keep])
            views.append(torch.full((len(keep),), i))
        hist = sum(color_histogram(v[..., :3], v[..., 3] / 255.0, self.cfg.color_bins) for v in target.views)
        descriptors = F.normalize(masked_mean(feats, torch.stack(alphas)), dim=-1)
        self._reference = Reference(descriptors=descriptors, cells=torch.cat(cells),
                                    cell_views=torch.cat(views), histogram=hist / len(target.views),
                                    aspect=float(np.median(aspects)))

    @property
    def reference(self) -> Reference:
        if self._reference is None:
            raise MatcherError(f"matcher {self.display_name}: call prepare(target) first")
        return self._reference

    # ------------------------------------------------------------------ signals
    @torch.inference_mode()
    def candidate_signals(self, frames: Frames) -> list[list[tuple[Candidate, dict[str, float]]]]:
        """Per frame, its candidates with their signals: what the verifier file weighs, and what it is fitted on.
        The locate map is the batch's (``frames.results``): computed once however many matchers ask for it."""
        cfg, ref = self.cfg, self.reference
        located = frames.results(self.locator)
        per_image, crops = [], []
        for image, result in zip(frames, located):
            plan = crop_boxes(image.shape[0], image.shape[1], self.locator.cfg.crops)
            found = locate(result.heatmap, plan, image.shape[:2], count=cfg.candidates, drop=cfg.region_drop,
                           aspect=ref.aspect, pad=cfg.pad)
            per_image.append(found)
            crops += [np.ascontiguousarray(image[c.box[1]:c.box[3], c.box[0]:c.box[2]]) for c in found]
        zoom = set(ZOOM_SIGNALS) & set(cfg.signals)  # none of them: no second pass (proto and margin cost effnet's)
        feats = self.zoomer.backbone.encode(crops).patches if zoom else None
        matches = [r.score for r in self.keypointer.match_batch(crops)] if "keypoints" in cfg.signals \
            else [0.0] * len(crops)
        out, k = [], 0
        for found in per_image:
            peaks = [c.peak for c in found]
            rows = []
            for i, cand in enumerate(found):
                others = peaks[:i] + peaks[i + 1:]
                signals = {}
                if zoom:
                    signals, view, cell = self._zoom_signals(crops[k], feats[k])
                    first = np.array([cell_centre(cand.box, self.zoomer.backbone.grid, cell)], np.float32)
                    cand = replace(cand, points=np.concatenate([first, cand.points]), view=view)
                signals.update(proto=cand.peak, margin=cand.peak - max(others) if others else 0.0,
                               keypoints=math.log1p(max(float(matches[k]), 0.0)))
                rows.append((cand, {s: signals[s] for s in cfg.signals}))
                k += 1
            out.append(rows)
        return out

    def _zoom_signals(self, crop: np.ndarray, cells: torch.Tensor) -> tuple[dict[str, float], int, int]:
        """The zoomed signals, the view whose descriptor the candidate's is closest to, and its most
        reference-like cell."""
        ref = self.reference
        likeness = self._likeness(cells)
        weight = (likeness - likeness.median()).clamp(min=0)
        if float(weight.sum()) <= 0:
            weight = torch.ones_like(weight)
        descriptor = masked_mean(cells, weight)
        cosines = F.normalize(descriptor, dim=0) @ ref.descriptors.T
        cycle = part_matches(ref.cells, ref.cell_views, cells, "mutual", 1.0)[0]
        grid = self.zoomer.backbone.grid
        pixels = cv2.resize(weight.reshape(grid, grid).numpy().astype(np.float32), (crop.shape[1], crop.shape[0]),
                            interpolation=cv2.INTER_LINEAR)
        color = bhattacharyya(color_histogram(crop, pixels, self.cfg.color_bins), ref.histogram)
        return {"desc": float(cosines.max()), "cycle": cycle, "color": color}, int(cosines.argmax()), \
            int(likeness.argmax())

    def _likeness(self, cells: torch.Tensor) -> torch.Tensor:
        """Per zoom cell, its best cosine with a view's descriptor: how much it looks like the target."""
        return (F.normalize(cells, dim=-1) @ self.reference.descriptors.T).amax(1)

    @torch.inference_mode()
    def _refined(self, images: list[np.ndarray], best: list[Candidate]) -> list[Candidate]:
        """Each image's best candidate with its first point found again in a second, closer zoom (module doc,
        step 5); unchanged without the zoom."""
        if not best or any(c.view is None for c in best):
            return best
        squares = [square_around(tuple(c.points[0]), max(REFINE_MIN_SIDE, REFINE_SHARE * max(
            c.box[2] - c.box[0], c.box[3] - c.box[1])), (image.shape[1], image.shape[0]))
            for image, c in zip(images, best)]
        feats = self.zoomer.backbone.encode([np.ascontiguousarray(image[y0:y1, x0:x1])
                                             for image, (x0, y0, x1, y1) in zip(images, squares)]).patches
        grid = self.zoomer.backbone.grid
        out = []
        for image, c, (x0, y0, x1, y1), f in zip(images, best, squares, feats):
            colour = backprojection(image, self.reference.histogram, self.cfg.color_bins)[y0:y1, x0:x1]
            colour = cv2.resize(colour, (grid, grid), interpolation=cv2.INTER_AREA).reshape(-1)
            cell = int(np.argmax(self._likeness(f).numpy() + REFINE_COLOUR * colour))
            first = np.array([cell_centre((x0, y0, x1, y1), grid, cell)], np.float32)
            out.append(replace(c, points=np.concatenate([first, c.points])))
        return out

    # ------------------------------------------------------------------ decision
    def _match_batch(self, frames: Frames) -> list[MatchResult]:
        spec = self.decision
        per_image = self.candidate_signals(frames)
        scores = [np.array([verdict(spec, signals) for _, signals in rows], np.float32) for rows in per_image]
        cands = [[c for c, _ in rows] for rows in per_image]
        best = [int(s.argmax()) for s in scores]
        closer = [i for i, s in enumerate(scores) if s.max() >= self.cfg.refine_floor]
        for i, refined in zip(closer, self._refined([frames[i] for i in closer], [cands[i][best[i]] for i in closer])):
            cands[i][best[i]] = refined
        results = []
        for found, s, b in zip(cands, scores, best):
            order = [b] + [i for i in range(len(found)) if i != b]  # the best candidate's points first
            views = [c.view for c in found]
            results.append(MatchResult(
                score=float(s.max()), points=np.concatenate([found[i].points for i in order]),
                point_scores=np.concatenate([np.full(len(found[i].points), s[i], np.float32) for i in order]),
                boxes=np.array([c.box for c in found], np.float32), box_scores=s,
                box_views=None if None in views else np.array(views, np.int64)))
        return results

