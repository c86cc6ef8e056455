"""``PinDetector``: a pin_match matcher behind the interface PIN's agent expects of its detector.

PIN's ``CowObsPreprocessor`` (models/navigator/mod_iin_cow_navigator.py) builds its detector
once, calls ``reset()`` at every episode start, and at every step cuts the portrait frame into
a top and a bottom square, resizes each to ``cow.resize_dim`` and calls
``forward(square, pin_goal[0], category=captions)`` on each. It pastes the returned maps back
(nearest), counts the matched pixels and declares the goal found when the count is > 0. So
``forward`` must return a CPU float tensor of the square's size with 1.0 at matched pixels,
as PIN's ``PersOwl`` and ``DINOMatcher`` do; the threshold is applied here, never in the matcher.

The agent hands over one square at a time. A square is one crop under both crop policies of
``pin_match.contract.crops`` (``pin`` and ``whole`` alike), so the matcher scores exactly the square the
agent shows it, and the frame's verdict (either square matched) is the agent's own max over
its two squares.

Under a stop policy other than PIN's first match (``policy="look:20"``: look 20 more steps after the
first firing, then commit to the best candidate) the detector runs the policy itself, with the same
code as the offline estimate (``StopPolicy.decide`` on the steps so far): a step's score is the
best of its squares, every map is empty until the policy commits, and at the step where it does,
``committed`` names the candidate's step, score and per-square maps (the last square's call returns
that square's map of the candidate). The agent places the goal from the candidate's own frame: it
keeps the depth and pose of the last ``window`` steps.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pin_match import atomic
from pin_match.contract.matcher import N_DESCRIPTIONS, N_VIEWS, ConfigError, Matcher, MatchResult, Modality, Target
from pin_match.contract.registry import create_matcher
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.sigma import SigmaChoice, SigmaError, resolve_sigma, thresholds_path
from pin_match.evaluation.core.stop import FIRST_MATCH, LookFurther, StopPolicy, one_walk


class PinAgentError(PinMatchError, ValueError):
    """The agent called the detector out of order or with inputs PIN never produces."""


@dataclass(frozen=True)
class Commit:
    """The candidate a stop policy committed to: its step (0-based since ``reset``), its score (the best of its
    squares), each square's map at sigma (in the order the agent passed them) and the step where the policy
    committed."""

    step: int
    score: float
    maps: tuple[torch.Tensor, ...]
    at_step: int


class PinDetector:
    """Detector for PIN's modular agent around any registered matcher.

    ``PinDetector("effnet", thresholds="thresholds/effnet.json")``, ``PinDetector("dino",
    thresholds="paper")`` or ``PinDetector("color", sigma=0.8)``; extra keywords are the
    matcher's config. ``sigma_choice`` says where sigma came from; ``last_result`` and
    ``last_score`` hold the matcher's verdict on the last square, for the researcher's logs.
    """

    def __init__(self, matcher: str | Matcher, *, sigma: float | None = None, thresholds: str | Path | None = None,
                 resize_dim: int | None = 224, policy: str | StopPolicy = FIRST_MATCH, squares_per_step: int = 2,
                 **matcher_cfg: Any) -> None:
        if isinstance(matcher, Matcher):
            if matcher_cfg:
                raise ConfigError(f"PinDetector: config keys {sorted(matcher_cfg)} go with a matcher name, not with "
                                  f"the built matcher {matcher.id}")
        else:
            matcher = create_matcher(matcher, **matcher_cfg)
        if matcher.modality is Modality.CATEGORY:
            raise PinAgentError(f"matcher {matcher.id} reads the category label, which PIN's agent never hands its "
                                "detector (forward gets the square, the references and the descriptions)")
        if resize_dim is not None and resize_dim < 8:
            raise PinAgentError(f"resize_dim={resize_dim}: PIN resizes each square to resize_dim x resize_dim pixels")
        self.matcher = matcher
        self.sigma_choice: SigmaChoice = resolve_sigma(matcher.id, matcher.default_sigma, sigma, thresholds)
        if thresholds is not None:
            _check_tuned_for(thresholds, matcher)
        self.resize_dim = resize_dim
        self.policy = StopPolicy.parse(policy) if isinstance(policy, str) else policy
        if isinstance(self.policy, LookFurther) and self.policy.upper_bound:
            raise PinAgentError(f"stop policy {self.policy} reads where the recording ends, which an agent does not "
                                "know: give the detector a window (look:W)")
        if squares_per_step < 1:
            raise PinAgentError(f"squares_per_step={squares_per_step}: PIN passes 2 squares a step")
        self.squares_per_step = squares_per_step
        self.last_result: MatchResult | None = None
        self.committed: Commit | None = None
        self._episode_open = False
        self._prepared = False
        self._steps: list[list[MatchResult]] = []

    @classmethod
    def from_cow_config(cls, cow: Mapping[str, Any], device: Any = None) -> PinDetector:
        """From the ``cow`` section of a PIN config: matcher, thresholds or sigma, resize_dim, policy, matcher_cfg."""
        if cow.get("matcher") is None:
            raise ConfigError("cow.matcher: name the pin_match matcher (e.g. effnet) when cow.method is pin_match")
        matcher_cfg = {key: tuple(value) if isinstance(value, Sequence) and not isinstance(value, str) else value
                       for key, value in dict(cow.get("matcher_cfg") or {}).items()}  # YAML lists: tuple fields
        if device is not None:
            matcher_cfg.setdefault("device", str(device))
        return cls(str(cow["matcher"]), sigma=cow.get("sigma"), thresholds=cow.get("thresholds"),
                   resize_dim=cow.get("resize_dim", 224), policy=cow.get("policy") or FIRST_MATCH, **matcher_cfg)

    @property
    def sigma(self) -> float:
        return self.sigma_choice.value

    @property
    def last_score(self) -> float | None:
        return None if self.last_result is None else self.last_result.score

    def reset(self) -> None:
        """A new episode: the next ``forward`` prepares the matcher for its references, once."""
        self._episode_open = True
        self._prepared = False
        self.last_result = None
        self.committed = None
        self._steps = []

    def forward(self, obs: Any, references: Any, category: Sequence[str] | None = None) -> torch.Tensor:
        """Map of the square ``obs`` (H x W float32, CPU): 1.0 at ``points_at(sigma)``, all zero below sigma."""
        if not self._episode_open:
            raise PinAgentError("PinDetector.forward before reset(): PIN's preprocessor resets the detector at the "
                                "start of every episode (CowObsPreprocessor.reset)")
        image = _square(obs, self.resize_dim)
        if not self._prepared:
            self.matcher.prepare(episode_target(references, category, self.matcher))
            self._prepared = True
        self.last_result = self.matcher.match(image)
        square_map = points_map(self.last_result.points_at(self.sigma), image.shape[0], image.shape[1])
        if self.policy == FIRST_MATCH:
            return square_map
        return self._under_policy(square_map)

    def _under_policy(self, square_map: torch.Tensor) -> torch.Tensor:
        """Keep the square's result; after a step's last square, ask the policy whether it commits now."""
        if not self._steps or len(self._steps[-1]) == self.squares_per_step:
            self._steps.append([])
        self._steps[-1].append(self.last_result)  # type: ignore[arg-type]  # set by forward
        empty = torch.zeros_like(square_map)
        if self.committed is not None or len(self._steps[-1]) < self.squares_per_step:
            return empty
        scores = np.array([max(r.score for r in step) for step in self._steps])
        decision = self.policy.decide(one_walk(scores), self.sigma, walk_goes_on=True)[0]
        if decision.stop is None:
            return empty
        chosen = self._steps[decision.chosen]  # type: ignore[index]  # a committed decision names its candidate
        maps = tuple(points_map(r.points_at(self.sigma), *square_map.shape) for r in chosen)
        self.committed = Commit(int(decision.chosen), float(scores[decision.chosen]), maps,  # type: ignore[arg-type]
                                len(scores) - 1)
        return maps[-1]

    __call__ = forward  # PIN calls its detector as a module: self.clip_module(square, references, category=...)

    def __repr__(self) -> str:
        return f"PinDetector({self.matcher.id}, sigma={self.sigma:.6g} ({self.sigma_choice.source}))"


def _check_tuned_for(thresholds: str | Path, matcher: Matcher) -> None:
    """A sigma tuned under another config of the same matcher is refused: it is not that matcher's sigma."""
    data = atomic.read_json(thresholds_path(thresholds), SigmaError, "thresholds file")  # resolve_sigma read it
    tuned_id = data.get("matcher_id") if isinstance(data, dict) else None
    if tuned_id is not None and tuned_id != matcher.id:
        raise SigmaError(f"{thresholds_path(thresholds)} was tuned for {tuned_id}, but the detector's matcher is "
                         f"{matcher.id} (another config or version): tune this config, or build the detector with "
                         "the tuned config")


def _square(obs: Any, resize_dim: int | None) -> np.ndarray:
    """The agent's square (a PIL image in PIN) as H x W x 3 uint8."""
    if hasattr(obs, "convert") and hasattr(obs, "size"):  # a PIL image, without importing PIL here
        obs = obs.convert("RGB")
    image = np.array(obs)  # a writable copy: PIL's buffer is read-only, and torch.from_numpy warns on it
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise PinAgentError(f"PinDetector.forward: obs must be an RGB PIL image or H x W x 3 uint8, got "
                            f"{image.shape} {image.dtype}")
    if resize_dim is not None and image.shape[:2] != (resize_dim, resize_dim):
        raise PinAgentError(f"PinDetector.forward: obs is {image.shape[1]}x{image.shape[0]}, but the detector was "
                            f"built for resize_dim={resize_dim}: give it the same cow.resize_dim as the preprocessor")
    return image


def episode_target(references: Any, descriptions: Sequence[str] | None, matcher: Matcher) -> Target:
    """The target of PIN's ``pin_goal``: views = ``pin_goal[0]`` (alpha = mask), descriptions = ``pin_goal[1]``.

    PIN knows no object id here; the target is named by a hash of its views, so messages and
    per-target warnings stay distinct between episodes.
    """
    refs = np.asarray(references)
    if refs.ndim != 4 or refs.shape[0] != N_VIEWS or refs.shape[3] != 4 or refs.dtype != np.uint8:
        raise PinAgentError(f"references must be PIN's pin_goal[0]: uint8 of shape ({N_VIEWS}, H, W, 4) with alpha = "
                            f"the object's mask, got {refs.shape} {refs.dtype}")
    for k, view in enumerate(refs):
        if not view[..., 3].any():
            raise PinAgentError(f"reference {k} has an all-zero alpha channel: PIN's references carry the object's "
                                "mask in alpha")
    if descriptions is None:
        if matcher.modality is not Modality.VISUAL:
            raise PinAgentError(f"matcher {matcher.id} reads descriptions, but the agent passed category=None (PIN "
                                "passes pin_goal[1] for portrait frames only when it is a list)")
        descriptions = ("",) * N_DESCRIPTIONS  # a visual matcher never reads them
    if isinstance(descriptions, str) or len(descriptions) != N_DESCRIPTIONS or \
            not all(isinstance(d, str) for d in descriptions):
        raise PinAgentError(f"category must be PIN's pin_goal[1], a list of {N_DESCRIPTIONS} descriptions, got "
                            f"{str(descriptions)[:80]}")
    name = "pin-" + hashlib.sha256(np.ascontiguousarray(refs).tobytes()).hexdigest()[:12]
    return Target(object_id=name, category="", views=tuple(refs), descriptions=tuple(descriptions))


def points_map(points: np.ndarray, height: int, width: int) -> torch.Tensor:
    """1.0 at the pixel holding each point (x, y): row floor(y), column floor(x); PIN's map convention."""
    out = torch.zeros((height, width), dtype=torch.float32)
    if len(points):
        xs = torch.from_numpy(np.floor(points[:, 0]).astype(np.int64))
        ys = torch.from_numpy(np.floor(points[:, 1]).astype(np.int64))
        out[ys, xs] = 1.0
    return out
