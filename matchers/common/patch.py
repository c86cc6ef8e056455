"""What every patch-similarity matcher shares (``dino``, ``dinov2``, ``clip``, ``clip-text``, the feature-map ones).

Every observation patch is compared by cosine with a few target vectors (one prototype per
reference view, or one text feature per description); its score is the max over targets,
the crop's score the max over patches, and every patch centre comes back as a point with its
own score so that ``points_at(sigma)`` gives the paper's "centres of the patches above sigma"
for any sigma. The math lives here, in ``PatchSimilarityMatcher`` and a few functions,
independent of the backbone, so a stub backbone with hand-set tokens checks it exactly; the
modules of the algorithms (``dino.py``, ``clip.py``, ``effnet.py`` ...) say which backbone
and which target vectors.
"""

from __future__ import annotations

import functools
import hashlib
import threading
from abc import abstractmethod
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np
import torch
import torch.nn.functional as F

from pin_match.contract import (
    ConfigError,
    CropConfig,
    CropMatcher,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    Target,
    WeightsError,
    WeightsSpec,
    create_matcher,
    misfit,
    weights_field,
)
from pin_match.matchers.common.backbones import PatchBackbone
from pin_match.nn.prototypes import masked_mean, patch_scores


def alpha_to_grid(alpha: np.ndarray, grid: int) -> torch.Tensor:
    """The reference's alpha mask in [0, 1] resized bilinearly to the patch grid, as PIN does.

    Plain bilinear sampling can miss an object much smaller than a patch (all weights 0, so
    no prototype); only then the area average is used instead, which is non-zero wherever
    the object is.
    """
    a = torch.from_numpy(np.ascontiguousarray(alpha)).float().div(255.0)[None, None]
    weights = F.interpolate(a, size=(grid, grid), mode="bilinear", align_corners=False)[0, 0]
    if float(weights.sum()) <= 0.0:
        weights = F.adaptive_avg_pool2d(a, (grid, grid))[0, 0]
    return weights


@functools.lru_cache(maxsize=64)
def patch_centres(grid: int, width: int, height: int) -> np.ndarray:
    """Row-major patch centres (x, y) at round((i + 0.5) x scale) in pixels of an image squashed to the grid.

    ``np.rint`` rounds halves to even, exactly as Python's ``round`` in the paper's formula.
    Every crop of a frame-set has the same size, so the array is computed once per (grid, size)
    and shared, read-only.
    """
    xs = np.rint((np.arange(grid) + 0.5) * (width / grid))
    ys = np.rint((np.arange(grid) + 0.5) * (height / grid))
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    centres = np.stack([xx.ravel(), yy.ravel()], axis=1).astype(np.float32)
    centres.setflags(write=False)
    return centres


@dataclass
class PatchConfig(CropConfig):
    """Backbone settings; ``model_name`` and ``img_size`` may name a smaller model for tests and ablations."""

    weights: str | None = weights_field()
    model_name: str = ""
    img_size: int = 224
    hub_id: str | None = field(default=None, metadata={"help": "hub repository of the weights; default: the "
                                                               "matcher's own"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.model_name:
            raise ConfigError(f"{type(self).__name__}: model_name must not be empty")
        if self.img_size < 8:
            raise ConfigError(f"{type(self).__name__}: img_size={self.img_size} is too small")


REMEMBERED_BYTES = 1280 * 2**20  # crop features a matcher keeps: a house's whole tour fits (356-501 frames in the
# default set, docs/synthetic.md; two crops each, 1 MB a crop at effnet's 196 x 1280 float32 tokens), so each of its
# episodes reads them again; 384 MB, a walk of 120 frames, made every episode of a tour run the network again


class SeenBatches:
    """The features of the crop batches a matcher met last, by a digest of their pixels and order: an exploration
    walk is read by every episode of its house (one target each), so its frames come again batch for batch and
    are not run through the network again. Whole batches only, so a result is the very one the network gave,
    whatever was met before; the oldest are dropped past ``budget`` bytes."""

    def __init__(self, budget: int = REMEMBERED_BYTES) -> None:
        self.budget, self.held = budget, 0
        self._seen: OrderedDict[bytes, torch.Tensor] = OrderedDict()
        self._lock = threading.Lock()  # a batch's parts are matched in threads of their own

    def features(self, images: Sequence[np.ndarray], encode: Callable[[], torch.Tensor]) -> torch.Tensor:
        key = batch_digest(images)
        with self._lock:
            known = self._seen.get(key)
            if known is not None:
                self._seen.move_to_end(key)
                return known.clone()
        known = encode()
        with self._lock:
            if key not in self._seen:
                self._seen[key] = known
                self.held += known.nbytes
            while self.held > self.budget and self._seen:
                self.held -= self._seen.popitem(last=False)[1].nbytes
        return known.clone()


def batch_digest(images: Sequence[np.ndarray]) -> bytes:
    """A digest of a batch's pixels, shapes and order."""
    h = hashlib.blake2b(digest_size=16)
    for image in images:
        h.update(repr((image.shape, image.dtype.str)).encode())
        h.update(np.ascontiguousarray(image).data)
    return h.digest()


class PatchSimilarityMatcher(CropMatcher):
    """Max-over-targets cosine between observation patches and target vectors.

    Subclasses say how the backbone is built (``_build_backbone``) and what the target
    vectors are (``_target_vectors``). A ready backbone may be passed in, which tests use
    for a stub and callers may use to share one loaded model between matchers.
    """

    Config: ClassVar[type[MatcherConfig]] = PatchConfig
    weights_spec: ClassVar[WeightsSpec]

    def __init__(self, cfg: MatcherConfig | None = None, *, backbone: PatchBackbone | None = None) -> None:
        super().__init__(cfg)
        self._backbone = backbone
        self._targets: torch.Tensor | None = None
        self._seen = SeenBatches()

    @property
    def backbone(self) -> PatchBackbone:
        """Built on first use, never at construction, so listing and configuring matchers stays offline."""
        if self._backbone is None:
            try:
                self._backbone = self._build_backbone()
            except WeightsError:
                raise
            except (RuntimeError, ValueError, KeyError, OSError) as exc:
                source = self.cfg.weights or self.cfg.hub_id or self.weights_spec.hub_id
                raise misfit(f"matcher {self.display_name}", source, self.cfg.model_name, exc) from exc
        return self._backbone

    @property
    def targets(self) -> torch.Tensor:
        """The prepared target vectors (T, D), unnormalised: one per reference view or per description."""
        if self._targets is None:
            raise MatcherError(f"matcher {self.display_name}: call prepare(target) first")
        return self._targets

    def checkpoint(self, names: Sequence[str]) -> Path:
        """The local weights file for this config: ``weights=`` when given, else the (cached) hub copy."""
        return self.weights_spec.resolve(self.cfg.weights, f"matcher {self.display_name}", names, self.cfg.hub_id)

    @abstractmethod
    def _build_backbone(self) -> PatchBackbone: ...

    @abstractmethod
    def _target_vectors(self, target: Target) -> torch.Tensor: ...

    def _prepare(self, target: Target) -> None:
        targets = self._target_vectors(target)
        if targets.ndim != 2 or not torch.isfinite(targets).all():
            raise MatcherError(f"matcher {self.display_name}: target {target.object_id} gave invalid target "
                               f"vectors of shape {tuple(targets.shape)}")
        self._targets = targets

    @torch.inference_mode()
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        backbone = self.backbone
        feats = self._seen.features(crops, lambda: backbone.encode(crops).patches)
        scores = patch_scores(feats, self.targets).numpy().astype(np.float32)
        grid = backbone.grid
        results = []
        for crop, s in zip(crops, scores):
            height, width = crop.shape[:2]
            results.append(MatchResult(score=float(s.max()), points=patch_centres(grid, width, height),
                                       point_scores=s, heatmap=s.reshape(grid, grid)))
        return results

    def embed_reference(self, view: np.ndarray) -> np.ndarray:
        """The backbone's global (CLS) embedding of the whole squashed RGB reference."""
        return self.backbone.encode([view[..., :3]]).cls[0].numpy().astype(np.float32)


class ReferencePrototypeMatcher(PatchSimilarityMatcher):
    """Visual targets: one mask-weighted patch-token prototype per reference view."""

    modality = Modality.VISUAL

    def _target_vectors(self, target: Target) -> torch.Tensor:
        backbone = self.backbone
        feats = backbone.encode([v[..., :3] for v in target.views]).patches
        alpha = torch.stack([alpha_to_grid(v[..., 3], backbone.grid).reshape(-1) for v in target.views])
        return masked_mean(feats, alpha)


def patch_matcher(name: str, **overrides) -> PatchSimilarityMatcher:
    """The registered matcher ``name``, refused unless it has patch tokens (effnet, dino, dinov2, clip ...).

    Feature stores and trained heads need a backbone's patch tokens; sift, color or owl have none.
    """
    matcher = create_matcher(name, **overrides)
    if not isinstance(matcher, PatchSimilarityMatcher):
        raise ConfigError(f"matcher {name!r} has no patch features (it is not a patch-similarity matcher); "
                          f"choose a patch backbone such as effnet, dino, dinov2 or clip")
    return matcher
