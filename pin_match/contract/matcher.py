"""The matcher contract: the target, the base classes, the config (the result is ``contract.results``'s).

It imports numpy and the rest of ``pin_match.contract`` (crops, frames, results, weights) only; nothing of
frame-sets, scoring or metrics. A plug-in imports everything it needs from
``pin_match.contract``.

The one interface every matcher shares: prepare once per target, then score images.

A matcher returns a score (higher = more likely the target) and the image points where
it believes the target is, each with its own score, and never applies a threshold: the
caller picks sigma, so one scoring pass serves every threshold, curve and tuning run.
The base class checks every result, so a broken plug-in fails loudly and by name.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum
from functools import cached_property
from typing import Any, ClassVar, Protocol

import numpy as np

from pin_match.contract.crops import POLICIES, Crop, crop_boxes
from pin_match.contract.frames import Frames
from pin_match.contract.results import N_VIEWS, MatchResult, extras_problem, points_problem
from pin_match.contract.weights import WeightsSpec
from pin_match.errors import PinMatchError


class Modality(str, Enum):
    VISUAL = "visual"      # reference views only
    TEXTUAL = "textual"    # descriptions only
    CATEGORY = "category"  # may read the category label (an ablation in the paper)


N_DESCRIPTIONS = 3  # human-written descriptions per target


class TargetError(PinMatchError, ValueError):
    """A target that is not what every matcher may assume (3 RGBA views with a mask, 3 descriptions)."""


@dataclass(frozen=True)
class Target:
    """What a matcher is told about the object to find."""

    object_id: str
    category: str
    views: tuple[np.ndarray, ...]  # RGBA uint8, view 0 frontal (30 deg yaw), 1 back, 2 top
    descriptions: tuple[str, ...]
    view_paths: tuple[str, ...] = field(default=(), compare=False)

    def __post_init__(self) -> None:
        if len(self.views) != N_VIEWS:
            raise TargetError(f"target {self.object_id}: expected {N_VIEWS} views, got {len(self.views)}")
        for i, view in enumerate(self.views):
            where = self.view_paths[i] if i < len(self.view_paths) else f"view {i}"
            if view.ndim != 3 or view.shape[2] != 4 or view.dtype != np.uint8:
                raise TargetError(
                    f"target {self.object_id}: {where} must be RGBA uint8, got shape {view.shape} {view.dtype}"
                )
            if not view[..., 3].any():
                raise TargetError(f"target {self.object_id}: {where} has an empty alpha mask")
        if len(self.descriptions) != N_DESCRIPTIONS:
            raise TargetError(
                f"target {self.object_id}: expected {N_DESCRIPTIONS} descriptions, got {len(self.descriptions)}"
            )

    @cached_property
    def fingerprint(self) -> str:
        """A digest of what a matcher is told (name, label, descriptions, views' pixels): two targets of one name
        from two frame-sets differ in it, so no batch lends one's results to the other (``Matcher.share_key``)."""
        h = hashlib.sha256(json.dumps([self.object_id, self.category, list(self.descriptions)]).encode())
        for view in self.views:
            h.update(str(view.shape).encode())
            h.update(np.ascontiguousarray(view).data)
        return h.hexdigest()[:16]


class MatcherError(PinMatchError, RuntimeError):
    """A matcher was misused or produced an invalid result."""


class ConfigError(PinMatchError, ValueError):
    """An unknown or ill-typed configuration key."""


def crops_field(default: str = "pin") -> Any:
    """The ``crops`` config field, for matchers that see frames through a crop policy."""
    return field(default=default, metadata={"help": f"crop policy, one of {', '.join(POLICIES)}"})


def weights_field() -> Any:
    """The ``weights`` config field, for matchers that load a checkpoint."""
    return field(default=None, metadata={"help": "local file or folder overriding the default weights"})


@dataclass
class MatcherConfig:
    """Settings shared by every matcher; subclasses add their own fields.

    Only ``device`` is common: a matcher declares ``crops: str = crops_field()`` and
    ``weights: str | None = weights_field()`` itself when it uses them, so a key that
    does nothing is refused instead of being hashed into a new id. Fields whose metadata
    says ``hash=False`` do not change results and stay out of the config hash.
    """

    device: str = field(default="cpu", metadata={"hash": False, "help": "torch device, e.g. cpu or cuda:0"})

    def __post_init__(self) -> None:
        crops = getattr(self, "crops", None)
        if crops is not None and crops not in POLICIES:
            raise ConfigError(f"crops={crops!r}: choose one of {POLICIES}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def hashed_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.metadata.get("hash", True)}


@dataclass
class CropConfig(MatcherConfig):
    """The config of a ``CropMatcher``: it sees frames through a crop policy."""

    crops: str = crops_field()


class PresetLike(Protocol):
    """What ``class Name(Base, preset=...)`` takes: a ``Preset`` (``pin_match.contract.preset``)."""

    def apply_to(self, cls: type[Matcher]) -> None: ...


class Matcher(ABC):
    """Base class: subclasses implement ``_prepare`` and ``_match_batch``.

    ``_match_batch`` receives a batch of RGB uint8 frames as a list of its own; the list is a
    ``Frames``, which a matcher built from others asks for their results (``contract.frames``).

    Class attributes describe the method for the registry, ``pin-match list`` and the docs.
    Bump ``version`` whenever the algorithm changes results, so stale caches are not reused.
    """

    name: ClassVar[str] = ""
    Config: ClassVar[type[MatcherConfig]] = MatcherConfig
    modality: ClassVar[Modality] = Modality.VISUAL
    default_sigma: ClassVar[float] = 0.5
    weights_spec: ClassVar[WeightsSpec | None] = None  # None: weight-free (or a composite of matchers that have one)
    paper: ClassVar[str] = ""
    version: ClassVar[int] = 1
    # True when match_batch is thread-safe after prepare: scoring then spreads frames over threads
    parallel_frames: ClassVar[bool] = False

    def __init_subclass__(cls, preset: PresetLike | None = None, **kwargs: Any) -> None:
        """``class Name(Base, preset=Preset(...))``: a named variant of ``Base`` set by data (see ``Preset``)."""
        super().__init_subclass__(**kwargs)
        if preset is not None:
            preset.apply_to(cls)

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else self.Config()
        if not isinstance(self.cfg, self.Config):
            raise ConfigError(f"{self.display_name}: config must be {self.Config.__name__}, got "
                              f"{type(self.cfg).__name__}")
        self._target: Target | None = None
        self._hash: tuple[str, str] | None = None  # (what it was computed from, the hash)

    # ------------------------------------------------------------------ identity
    @property
    def display_name(self) -> str:
        return self.name or type(self).__name__

    @property
    def config_hash(self) -> str:
        """Hash of name, version, config and the weights' identity (content for local files), never of a path.

        Computed once (a ``weights`` folder is walked and read to hash it): again only when the
        config, the version, the weights' source or a part's id has changed since.
        """
        parts = {role: part.id for role, part in self.parts().items()}
        state = repr((self.display_name, self.version, self.cfg, self.weights_spec, parts))
        if self._hash is None or self._hash[0] != state:
            config = self.cfg.hashed_dict()
            weights = config.pop("weights", None)
            payload = dict(matcher=self.display_name, version=self.version, config=config)
            if self.weights_spec is not None:
                payload["weights"] = self.weights_spec.identity(weights)
            if parts:  # a new version of a part never reuses the composite's caches
                payload["parts"] = parts
            self._hash = (state, hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode())
                          .hexdigest()[:12])
        return self._hash[1]

    @property
    def id(self) -> str:
        """Registry name plus config hash, e.g. ``dinov2@3f9a1c2b7d10``."""
        return f"{self.display_name}@{self.config_hash}"

    # ------------------------------------------------------------------ public API
    def prepare(self, target: Target) -> None:
        """Build everything derived from the target once (prototypes, text features, keypoints). A matcher already
        prepared for this very target (its content: ``Target.fingerprint``) keeps what it built: a part another
        matcher of the run shares (``share_parts``) is prepared once for both."""
        if self.modality is not Modality.CATEGORY:
            target = dataclasses.replace(target, category="")  # the label is off limits
        if self._target is not None and self._target.fingerprint == target.fingerprint:
            return
        self._target = None  # a prepare that fails half-way leaves nothing that claims to be prepared
        self._prepare(target)
        self._target = target

    def match(self, image: np.ndarray) -> MatchResult:
        return self.match_batch([image])[0]

    def match_batch(self, images: Sequence[np.ndarray]) -> list[MatchResult]:
        """The results on ``images`` (RGB, RGBA or grey, uint8); parts run once on them (``contract.frames``)."""
        return self.match_frames(Frames(images))

    def match_frames(self, frames: Frames) -> list[MatchResult]:
        """The results on a batch that other matchers may share: computed here, the parts' results borrowed from
        ``frames``. ``frames.results(matcher)`` computes them once for all who ask."""
        if self._target is None:
            raise MatcherError(f"matcher {self.display_name}: call prepare(target) before match()")
        for i, image in enumerate(frames):
            self._check_image(image, i)
        results = self._match_batch(frames.for_one())
        if len(results) != len(frames):
            raise MatcherError(f"matcher {self.display_name} returned {len(results)} results for "
                               f"{len(frames)} images")
        for image, result in zip(frames, results):
            self._validate(result, image.shape[0], image.shape[1])
        return results

    @property
    def share_key(self) -> tuple[str, str, str]:
        """What a batch lends this matcher's results under (``Frames.results``): its id, its device (a network's
        last bits differ between devices) and the target it is prepared for (its content, not only its name)."""
        if self._target is None:
            raise MatcherError(f"matcher {self.display_name}: call prepare(target) before match()")
        return (self.id, self.cfg.device, self._target.fingerprint)

    def parts(self) -> dict[str, Matcher]:
        """The matchers a composite is built from, by role (their weights are listed by ``pin-match list``)."""
        return {}

    def share_parts(self, peers: Sequence[Matcher]) -> None:
        """Take the run's other matchers (``peers``) in place of parts configured alike: a composite's job
        (``matchers.common.composite``); a matcher without parts has none to share."""
        return None

    @property
    def score_scale(self) -> str:
        """What a score's level means: a short name, a colon, then how it was read (``pin-match list`` shows the
        name, the report the whole; every table stores it). A raw score's level may differ per target, so
        one sigma may not carry to a house nobody tuned it on."""
        return "raw: the matcher's own score, not normalised per target"

    def target_notes(self) -> dict[str, Any]:
        """What ``prepare`` derived for the current target that explains the level of its scores (JSON values).

        The scoring engine stores it per target in the score table and the report shows it beside
        the target's scores (``cohort-norm``: the cohort's scores and scale). Empty by default.
        """
        return {}

    def embed_reference(self, view: np.ndarray) -> np.ndarray:
        """A global embedding of one RGBA reference (the paper's similarity analysis)."""
        raise MatcherError(f"matcher {self.display_name} has no global embedding for the similarity analysis")

    # ------------------------------------------------------------------ to implement
    @abstractmethod
    def _prepare(self, target: Target) -> None: ...

    @abstractmethod
    def _match_batch(self, images: list[np.ndarray]) -> list[MatchResult]: ...

    # ------------------------------------------------------------------ checks
    def _check_image(self, image: np.ndarray, index: int) -> None:
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise MatcherError(f"matcher {self.display_name}: image {index} must be H x W x 3 uint8, got "
                               f"{image.shape} {image.dtype}")
        if image.shape[0] < 8 or image.shape[1] < 8:
            raise MatcherError(f"matcher {self.display_name}: image {index} is too small ({image.shape[:2]})")

    def _validate(self, r: MatchResult, height: int, width: int) -> None:
        who = f"matcher {self.display_name}"
        if not isinstance(r, MatchResult):
            raise MatcherError(f"{who} returned {type(r).__name__}, expected MatchResult")
        if not isinstance(r.score, (float, int, np.floating, np.integer)) or not math.isfinite(float(r.score)):
            raise MatcherError(f"{who} returned a non-finite score {r.score!r}")
        r.score = float(r.score)
        problem = points_problem(r, height, width) or extras_problem(r)
        if problem:
            raise MatcherError(f"{who} {problem}")
        if r.boxes is not None:
            r.boxes = np.asarray(r.boxes, np.float32).reshape(-1, 4)


def class_problems(cls: type[Matcher]) -> list[str]:
    """What keeps a matcher class from working under this contract, each with its fix (empty when none).

    A contract base class may need config fields (``CropMatcher`` reads ``crops``): a ``Config``
    that does not derive from its ``Config`` would fail deep inside matching, so it is named here.
    """
    problems = []
    for base in cls.__mro__[1:]:
        if base.__module__ == __name__ and issubclass(base, Matcher) and not issubclass(cls.Config, base.Config):
            problems.append(f"its Config {cls.Config.__name__} must derive from {base.Config.__name__}, which "
                            f"{base.__name__} needs: write `class {cls.Config.__name__}({base.Config.__name__})`")
            break
    return problems


class CropMatcher(Matcher):
    """A matcher that sees the frame through the configured crop policy.

    Subclasses implement ``_match_crops``, which receives every crop of the whole batch
    at once (so a backbone runs one batch) and returns results in crop pixel coordinates;
    this class maps points back to the frame and takes the max over crops.
    """

    Config: ClassVar[type[MatcherConfig]] = CropConfig

    @abstractmethod
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]: ...

    def _match_batch(self, images: list[np.ndarray]) -> list[MatchResult]:
        plans = [crop_boxes(im.shape[0], im.shape[1], self.cfg.crops) for im in images]
        flat = [np.ascontiguousarray(c.take(im)) for im, boxes in zip(images, plans) for c in boxes]
        crop_results = self._match_crops(flat)
        if len(crop_results) != len(flat):
            raise MatcherError(f"matcher {self.display_name} returned {len(crop_results)} results for "
                               f"{len(flat)} crops")
        out, k = [], 0
        for boxes in plans:
            parts = crop_results[k:k + len(boxes)]
            k += len(boxes)
            out.append(merge_crop_results(parts, boxes))
        return out


def merge_crop_results(parts: Sequence[MatchResult], boxes: Sequence[Crop]) -> MatchResult:
    """Frame score = max over crops; points of all crops, mapped into frame pixels."""
    scores = np.array([float(p.score) for p in parts], np.float32)
    points = np.concatenate([b.to_frame(p.points) for p, b in zip(parts, boxes)]) if parts else np.zeros((0, 2))
    point_scores = np.concatenate([p.scores_of_points() for p in parts]).astype(np.float32)
    heatmaps = [p.heatmap for p in parts]
    heatmap = np.stack(heatmaps) if all(h is not None for h in heatmaps) and \
        len({h.shape for h in heatmaps}) == 1 else None
    boxes_out, box_scores, box_views = None, None, None
    boxed = [(p, b) for p, b in zip(parts, boxes) if p.boxes is not None]
    if boxed:
        boxes_out = np.concatenate([p.boxes.reshape(-1, 4) + np.array([b.x0, b.y0, b.x0, b.y0], np.float32)
                                    for p, b in boxed])
        box_scores = np.concatenate([p.box_scores for p, _ in boxed])
        if all(p.box_views is not None for p, _ in boxed):
            box_views = np.concatenate([p.box_views for p, _ in boxed])
    return MatchResult(score=float(scores.max()), points=points.astype(np.float32), point_scores=point_scores,
                       crop_scores=scores, heatmap=heatmap, boxes=boxes_out, box_scores=box_scores,
                       box_views=box_views)
