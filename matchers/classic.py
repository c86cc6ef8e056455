"""Weight-free matchers: real signal with no download, so the whole toolkit runs offline.

``sift`` finds the target by its texture (local features verified by a geometric model);
``color`` by its colour distribution (Swain & Ballard's ratio-histogram back-projection).
They bracket what appearance alone can do without learned features, and give every
metric, curve and notebook real numbers on a fresh machine.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import cv2
import numpy as np

from pin_match.contract import (
    CropConfig,
    CropMatcher,
    Matcher,
    MatcherConfig,
    MatchResult,
    Modality,
    Target,
    register_matcher,
)


def object_pixels(view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RGB and boolean alpha mask of an RGBA reference."""
    return view[..., :3], view[..., 3] > 127


# --------------------------------------------------------------------------- SIFT
@dataclass
class SiftConfig(MatcherConfig):
    ratio: float = 0.8             # Lowe's ratio test
    ransac_px: float = 6.0         # reprojection threshold of the similarity model
    max_features: int = 2000       # observation keypoints kept (strongest first)
    min_scale: float = 0.02        # reject degenerate models (object scale in the frame vs reference)
    max_scale: float = 8.0
    min_inliers: int = 5           # fewer inliers are not a verified model: the reference scores 0


@register_matcher("sift")
class SiftMatcher(Matcher):
    """SIFT + ratio test + RANSAC similarity transform, per reference view.

    Score = the largest number of RANSAC inliers over the 3 references. Each verified
    observation keypoint is a point whose score is the inlier count of its reference, so
    ``points_at(sigma)`` returns the keypoints of every reference that clears sigma.
    A similarity transform (4 degrees of freedom) rather than a homography: small
    objects seen from afar yield few matches, and 2 suffice to hypothesise it. But any 2
    matches fit a similarity exactly, so 2 inliers prove nothing: a model counts only with
    ``min_inliers`` or more, else the reference scores 0. On real photos without the
    target (scikit-image photos with other objects pasted, pin_match.data.sources.recolour seeds 0-2)
    chance models reached 2 in 42 of 72 frames and at most 4; the target scored 5 or more
    in 80 of its 90 frames. With ``min_inliers`` 5 no such frame scores above 0, and the
    first-match, F1 and Youden objectives all choose sigma 5 there: the default.
    """

    Config = SiftConfig
    modality = Modality.VISUAL
    version = 2
    default_sigma = 5.0
    paper = "Lowe, Distinctive Image Features from Scale-Invariant Keypoints, IJCV 2004"
    parallel_frames = True

    def __init__(self, cfg: SiftConfig | None = None) -> None:
        super().__init__(cfg)
        self._local = threading.local()
        self._refs: list[tuple[np.ndarray, np.ndarray]] = []

    def _detector(self, n: int = 0) -> cv2.SIFT:
        key = f"sift{n}"
        if not hasattr(self._local, key):
            setattr(self._local, key, cv2.SIFT_create(nfeatures=n))
        return getattr(self._local, key)

    def _prepare(self, target: Target) -> None:
        self._refs = []
        for view in target.views:
            rgb, alpha = object_pixels(view)
            gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
            kps, desc = self._detector().detectAndCompute(gray, alpha.astype(np.uint8) * 255)
            coords = np.array([k.pt for k in kps], np.float32).reshape(-1, 2)
            self._refs.append((coords, desc if desc is not None else np.zeros((0, 128), np.float32)))

    def _match_batch(self, images: list[np.ndarray]) -> list[MatchResult]:
        return [self._match_one(im) for im in images]

    def _match_one(self, image: np.ndarray) -> MatchResult:
        gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        kps, desc = self._detector(self.cfg.max_features).detectAndCompute(gray, None)
        obs = np.array([k.pt for k in kps], np.float32).reshape(-1, 2)
        per_ref = [self._verify(ref_xy, ref_desc, obs, desc) for ref_xy, ref_desc in self._refs]
        counts = np.array([len(p) for p in per_ref], np.float32)
        points = np.concatenate(per_ref) if per_ref else np.zeros((0, 2), np.float32)
        point_scores = np.concatenate([np.full(len(p), c, np.float32) for p, c in zip(per_ref, counts)])
        return MatchResult(score=float(counts.max(initial=0.0)), points=points, point_scores=point_scores)

    def _verify(self, ref_xy: np.ndarray, ref_desc: np.ndarray, obs_xy: np.ndarray,
                obs_desc: np.ndarray | None) -> np.ndarray:
        """Observation keypoints verified against one reference (their count is the evidence)."""
        if obs_desc is None or len(ref_desc) < 2 or len(obs_desc) < 2:
            return np.zeros((0, 2), np.float32)
        pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(ref_desc, obs_desc, k=2)
        good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < self.cfg.ratio * n.distance]
        if len(good) < 2:
            return np.zeros((0, 2), np.float32)
        src = ref_xy[[m.queryIdx for m in good]]
        dst = obs_xy[[m.trainIdx for m in good]]
        model, inliers = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC,
                                                     ransacReprojThreshold=self.cfg.ransac_px,
                                                     maxIters=2000, confidence=0.995, refineIters=10)
        if model is None or inliers is None:
            return np.zeros((0, 2), np.float32)
        scale = float(np.hypot(model[0, 0], model[1, 0]))
        if not self.cfg.min_scale <= scale <= self.cfg.max_scale:
            return np.zeros((0, 2), np.float32)
        keep = inliers.ravel().astype(bool)
        _, first = np.unique(dst[keep], axis=0, return_index=True)  # one point per observation keypoint
        if len(first) < self.cfg.min_inliers:
            return np.zeros((0, 2), np.float32)
        return dst[keep][np.sort(first)]


# --------------------------------------------------------------------------- colour
@dataclass
class ColorConfig(CropConfig):
    bins_h: int = 18
    bins_s: int = 8
    bins_v: int = 4
    work_size: int = 96            # each crop is resized to this many pixels a side
    windows: tuple[int, ...] = (6, 12, 24)  # window sides in work pixels (multi-scale)
    stride: int = 4                # spacing of candidate window centres in work pixels


@register_matcher("color")
class ColorMatcher(CropMatcher):
    """Ratio-histogram back-projection of the reference colours (Swain & Ballard 1991).

    The reference HSV histogram M (alpha pixels of all 3 views) and the crop's own
    histogram I give each colour the ratio r = M/I: colours common in the target and
    rare in the scene stand out. Window means of a weight of r at several sizes are the
    candidates; the score is the best window, the points are window centres with their
    window score. Swain & Ballard's weight min(r, 1) saturates: a window of colours that
    are all rarer in the scene than in the target scores exactly 1, however distinctive,
    and on real photos (pin_match.data.sources.recolour seeds 0-2) 77 of 90 target frames and 23 of 126
    other frames scored 1.0, so no sigma told them apart. The weight r / (1 + r) keeps
    min(r, 1)'s order below r = 1 (where it is 0.5), is continuous and strictly increasing
    above, and never reaches 1. There it gives 214 distinct scores to 216 frames, and sigma
    0.78, the F1 and Youden optimum on those frames, is the default.
    """

    Config = ColorConfig
    modality = Modality.VISUAL
    version = 2
    default_sigma = 0.78
    paper = "Swain & Ballard, Color Indexing, IJCV 1991"
    parallel_frames = True

    def _bins(self, rgb: np.ndarray) -> np.ndarray:
        """Flat HSV bin index of every pixel (OpenCV hue runs 0-179)."""
        c = self.cfg
        hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV).astype(np.int32)
        h = hsv[..., 0] * c.bins_h // 180
        s = hsv[..., 1] * c.bins_s // 256
        v = hsv[..., 2] * c.bins_v // 256
        return (h * c.bins_s + s) * c.bins_v + v

    def _hist(self, bins: np.ndarray) -> np.ndarray:
        c = self.cfg
        hist = np.bincount(bins.ravel(), minlength=c.bins_h * c.bins_s * c.bins_v).astype(np.float64)
        return hist / max(hist.sum(), 1.0)

    def _prepare(self, target: Target) -> None:
        total = None
        for view in target.views:
            rgb, alpha = object_pixels(view)
            h = self._hist(self._bins(rgb)[alpha])
            total = h if total is None else total + h
        self._model = total / len(target.views)

    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        return [self._match_crop(c) for c in crops]

    def embed_reference(self, view: np.ndarray) -> np.ndarray:
        """The L2-normalised colour histogram of the object's pixels: what this matcher compares."""
        rgb, alpha = object_pixels(view)
        hist = self._hist(self._bins(rgb)[alpha]).astype(np.float32)
        return hist / max(float(np.linalg.norm(hist)), 1e-12)

    def _match_crop(self, crop: np.ndarray) -> MatchResult:
        c = self.cfg
        h, w = crop.shape[:2]
        small = cv2.resize(crop, (c.work_size, c.work_size), interpolation=cv2.INTER_AREA)
        bins = self._bins(small)
        ratio = self._model / np.maximum(self._hist(bins), 1e-12)
        weight = (ratio / (1.0 + ratio)).astype(np.float32)
        proj = weight[bins]
        best = np.max([cv2.boxFilter(proj, -1, (k, k), borderType=cv2.BORDER_REPLICATE) for k in c.windows], axis=0)
        half = c.stride // 2
        grid = best[half::c.stride, half::c.stride]
        ys, xs = np.mgrid[half:c.work_size:c.stride, half:c.work_size:c.stride]
        points = np.stack([(xs.ravel() + 0.5) * w / c.work_size, (ys.ravel() + 0.5) * h / c.work_size], 1)
        return MatchResult(score=float(grid.max()), points=points, point_scores=grid.ravel(), heatmap=grid)
