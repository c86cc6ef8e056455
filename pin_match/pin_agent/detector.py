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

Under a stop policy (``policy="look:20"``: look 20 more steps after the first firing, then commit
to the best candidate) the detector runs the policy itself, with the same code as the offline
estimate (``StopPolicy.decide`` on the steps so far, a step's score the best of its squares), so
live and offline give the same ``Decision`` on the same scores (``detector.decision``). Every map
is empty until the policy commits. A commit is declared at the first square after which no later
square of the step can change it: a commit to the present step (PIN's rule, k-of-n, a
house-relative line, a look-further window that ends on its best candidate) as soon as a square
decides it, and from that square on each square's call returns its own map of the candidate, at
the candidate's line; a commit to an earlier step (a window that ends on a better earlier
candidate) after the step's last square, whose call, the only one left, returns every square's
map of the candidate merged (its points are in another frame: the agent places them from
``committed``). ``committed`` then names the candidate's step, score and per-square maps. After
the commit PIN's rule goes on answering every square (its agent re-localises the goal at every
detection); any other policy returns empty maps (its goal is the committed candidate). ``reset(placeable=...)``
tells the detector which steps' candidates the agent can place (depth in range), as the offline
estimate's ``placeable``; a firing whose candidate cannot is passed over. The candidate may be
an earlier step's, so the agent places the goal from that step's depth and pose: it keeps the
last window's steps beside the detector. A house-relative line reads the house's level, kept
step by step (``stop.RunningLevel``), so no step reads the whole walk again for it.

Under an approach-verify policy (``policy="approach:1+0.6"``) a firing sends the agent to the candidate first:
after the step's last square, ``approaching`` names the candidate's step (its goal placed from
``candidate_maps(step)``, as a commit's). The steps the agent sees on its way are views of the candidate, not steps
of its walk: each one's distance to the candidate comes from ``reset(distance=...)``, asked once a view. At the
standing point the agent calls ``arrived()``: the policy decides on the views (the same ``decide``, the views given
as ``stop.CloseLook``) and commits (``committed``; the next call returns the candidate's maps merged, as a commit
to an earlier step does) or rejects the candidate. After a
rejection the agent walks back to its route, ``returning`` is true, the squares it passes are not looked at (empty
maps), and ``resume()`` takes the walk up again. ``reset(goal=...)`` gives each step's goal point: a rejected one is
remembered by the cells of the agent's map around it, and a later firing there is passed over without walking up to
it, as offline (``walkup.remembered_cells``).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pin_match import atomic
from pin_match.contract.matcher import N_DESCRIPTIONS, N_VIEWS, ConfigError, Matcher, MatchResult, Modality, Target
from pin_match.contract.registry import create_matcher
from pin_match.data.walkup import remembered_cells
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.sigma import SigmaChoice, SigmaError, resolve_sigma, thresholds_path
from pin_match.evaluation.core.stop import (
    FIRST_MATCH,
    ApproachVerify,
    CloseLook,
    Decision,
    LookFurther,
    Placeable,
    StopPolicy,
    one_walk,
)


class PinAgentError(PinMatchError, ValueError):
    """The agent called the detector out of order or with inputs PIN never produces."""


@dataclass(frozen=True)
class Commit:
    """The candidate a stop policy committed to: its step (0-based since ``reset``), its score (the best of its
    squares), each square's map at its line (in the order the agent passed them; a commit to the present step holds
    the squares seen so far) and the step where the policy committed."""

    step: int
    score: float
    maps: tuple[torch.Tensor, ...]
    at_step: int


class PinDetector:
    """Detector for PIN's modular agent around any registered matcher.

    ``PinDetector("effnet", thresholds="thresholds/effnet.json")``, ``PinDetector("dino",
    thresholds="paper")`` or ``PinDetector("color", sigma=0.8)``; extra keywords are the
    matcher's config. ``sigma_choice`` says where sigma came from; ``last_result`` and
    ``last_score`` hold the matcher's verdict on the last square, for the researcher's logs;
    ``decision`` the policy's ``Decision`` on the steps so far.
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
        self.policy = StopPolicy.parse(policy) if isinstance(policy, str) else policy
        if isinstance(self.policy, LookFurther) and self.policy.upper_bound:
            raise PinAgentError(f"stop policy {self.policy} reads where the recording ends, which an agent does not "
                                "know: give the detector a window (look:W)")
        self.sigma_choice: SigmaChoice = resolve_sigma(matcher.id, matcher.default_sigma, sigma, thresholds,
                                                       self.policy)
        if thresholds is not None:
            _check_tuned_for(thresholds, matcher)
        self.resize_dim = resize_dim
        if squares_per_step < 1:
            raise PinAgentError(f"squares_per_step={squares_per_step}: PIN passes 2 squares a step")
        self.squares_per_step = squares_per_step
        self.reset()
        self._episode_open = False

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

    def reset(self, placeable: Placeable | None = None, goal: Callable[[int], np.ndarray] | None = None,
              distance: Callable[[], float] | None = None) -> None:
        """A new episode: the next ``forward`` prepares the matcher for its references, once. ``placeable(step)``:
        can the candidate of that step (0-based since this reset) be placed in the house? The agent answers from the
        step's depth and ``candidate_maps(step)``; it may be asked again, and about the present step while its later
        squares are still to come (points added by a later square only make a candidate placeable). None: every
        candidate can (PIN's agent finds out itself). Under an approach-verify policy, ``goal(step)``: the goal point
        (x, y, z) the agent placed for that step's candidate, remembered once rejected by the cells of its map around
        it (``walkup.remembered_cells``; None: by the step itself); ``distance()``: the agent's distance now to the
        candidate it walks up to, in metres (needed by that policy)."""
        self._episode_open = True
        self._goal = goal
        self._distance = distance
        self.approaching: int | None = None  # the step whose candidate the agent walks up to
        self.returning = False  # walking back to its route after a rejection
        self._deliver = False  # a commit made at ``arrived``: the next call returns the candidate's map
        self._views: dict[int, list[tuple[float, float]]] = {}  # per candidate step, its views (distance, score)
        self._looks: dict[int, tuple[tuple[float, float], ...]] = {}  # per candidate walked up to, its views
        self._prepared = False
        self._placeable = placeable
        self.last_result: MatchResult | None = None
        self.committed: Commit | None = None
        self.decision: Decision | None = None
        self._steps: list[list[tuple[MatchResult, tuple[int, int]]]] = []  # per step, each square's result and size
        self._scores: list[float] = []  # per step, the best of its squares so far
        self._levels: list[float] = []  # per step, the house's level before it
        self._running = self.policy.running_level()

    def forward(self, obs: Any, references: Any, category: Sequence[str] | None = None) -> torch.Tensor:
        """Map of the square ``obs`` (H x W float32, CPU): under PIN's rule 1.0 at ``points_at(sigma)``, all zero below
        sigma; under a policy, the candidate's map from the square where it commits (module docstring)."""
        if not self._episode_open:
            raise PinAgentError("PinDetector.forward before reset(): PIN's preprocessor resets the detector at the "
                                "start of every episode (CowObsPreprocessor.reset)")
        image = _square(obs, self.resize_dim)
        if self.returning:
            return torch.zeros(image.shape[:2], dtype=torch.float32)
        if not self._prepared:
            if isinstance(self.policy, ApproachVerify) and self._distance is None:
                raise PinAgentError(f"stop policy {self.policy} weighs the views within {self.policy.distance:g} m of "
                                    "a candidate: reset(distance=...) must say how far the agent is from it")
            self.matcher.prepare(episode_target(references, category, self.matcher))
            self._prepared = True
        self.last_result = self.matcher.match(image)
        if self.approaching is not None:
            self._view(self.last_result.score)
            return torch.zeros(image.shape[:2], dtype=torch.float32)
        self._keep(self.last_result, image.shape[:2])
        if self.committed is None:
            self._decide()
        elif self.committed.step == len(self._steps) - 1:  # the candidate's later squares join its maps
            self.committed = self._commit(self.committed.step, self.committed.at_step)
        return self._answer()

    def arrived(self) -> None:
        """The agent stands beside the candidate it walked up to: the policy commits to it or rejects it (then the
        agent walks back, ``returning``, until ``resume``)."""
        if self.approaching is None:
            raise PinAgentError("PinDetector.arrived without an approach: the detector names the candidate to walk up "
                                "to in ``approaching``")
        views = self._views.pop(self.approaching, [])
        if views and len(views) * self.squares_per_step != self._view_squares:
            raise PinAgentError("PinDetector.arrived in the middle of a step: pass every square of the last view first")
        self._looks[self.approaching] = tuple(views)
        self.approaching = None
        self._decide()
        self.returning = self.committed is None
        self._deliver = self.committed is not None  # the next call answers with the candidate's map

    def resume(self) -> None:
        """The agent is back on its route after a rejection: its next steps are its walk's again."""
        if not self.returning:
            raise PinAgentError("PinDetector.resume without a rejection to walk back from")
        self.returning = False

    def _view(self, score: float) -> None:
        """A square seen on the way to the candidate: a view is a step's squares, its score their best."""
        views = self._views.setdefault(self.approaching, [])  # type: ignore[arg-type]  # approaching
        if self._view_squares % self.squares_per_step == 0:
            views.append((float(self._distance()), -np.inf))  # type: ignore[misc]  # reset checked it is set
        distance, best = views[-1]
        views[-1] = (distance, max(best, float(score)))
        self._view_squares += 1

    def _close_look(self, step: int) -> CloseLook:
        """A step's candidate as the policy meets it live: remembered by the cells around its goal point (by its step
        without ``goal``), its views once arrived."""
        if self._goal is None:
            return CloseLook(step, self._looks.get(step))
        key, around = remembered_cells(self._goal(step))
        return CloseLook(key, self._looks.get(step), around)

    def candidate_maps(self, step: int) -> tuple[torch.Tensor, ...]:
        """Each square's map of a step so far, at the step's line (sigma, or the policy's above it): the points a
        goal is placed from."""
        line = float(self.policy.line(one_walk(np.array(self._scores)), self.sigma, np.array(self._levels))[step])
        return tuple(points_map(result.points_at(line), *shape) for result, shape in self._steps[step])

    def _keep(self, result: MatchResult, shape: tuple[int, int]) -> None:
        """The square's result joins its step (a new step after the last one's ``squares_per_step`` squares)."""
        if not self._steps or len(self._steps[-1]) == self.squares_per_step:
            if self._scores:
                self._running.add(self._scores[-1])  # the step before has finished
            self._levels.append(self._running.level)
            self._steps.append([])
            self._scores.append(-np.inf)
        self._steps[-1].append((result, shape))
        self._scores[-1] = max(self._scores[-1], result.score)

    def _decide(self) -> None:
        """The policy on the steps so far; a commit is declared once the step's later squares cannot change it: a
        commit to the present step at once (a higher step score only counts more, its line reads earlier steps only,
        and a candidate placeable on part of its points is placeable on all), any other at the step's last square."""
        present = len(self._steps) - 1
        decision = self.policy.decide(one_walk(np.array(self._scores)), self.sigma, self._placeable,
                                      np.array(self._levels), verify=self._close_look)[0]
        complete = len(self._steps[-1]) == self.squares_per_step
        if not complete and (decision.stop, decision.chosen) != (present, present):
            return
        self.decision = decision
        if decision.approaching is not None:  # after the step's last square: the agent leaves its walk for it
            self.approaching, self._view_squares = decision.approaching, 0
        elif decision.stop is not None:
            self.committed = self._commit(int(decision.chosen), present)  # type: ignore[arg-type]  # a commit's

    def _commit(self, step: int, at_step: int) -> Commit:
        return Commit(step, float(self._scores[step]), self.candidate_maps(step), at_step)

    def _answer(self) -> torch.Tensor:
        """The map this square's call returns (module docstring)."""
        present, square = len(self._steps) - 1, len(self._steps[-1]) - 1
        result, shape = self._steps[present][square]
        commit = self.committed
        if commit is not None and self._deliver:  # committed on arrival: its map, once (points of another frame)
            self._deliver = False
            return torch.stack(commit.maps).amax(dim=0)
        if commit is not None and present == commit.step:
            return commit.maps[square]
        if commit is not None and present == commit.at_step:  # an earlier step's candidate: the one call left
            return torch.stack(commit.maps).amax(dim=0)
        if commit is not None and self.policy == FIRST_MATCH:
            return points_map(result.points_at(self.sigma), *shape)
        return torch.zeros(shape, dtype=torch.float32)

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
