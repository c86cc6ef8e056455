"""Approach-verify policies: walk up to a candidate, look again from close by, commit or reject it and walk on."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from pin_match.evaluation.core.metrics import FrameArrays
from pin_match.evaluation.core.stop.base import (
    CloseLook,
    Decision,
    Placeable,
    PolicyError,
    StopPolicy,
    Verify,
    committed_found,
    parsed_window,
    signed_text,
    window_suffix,
)


@dataclass(frozen=True)
class ApproachVerify(StopPolicy):
    """Walk up and check before stopping (IEVE's verify, UniGoal's blacklist): at a firing (a placeable candidate) the
    agent leaves its walk for the candidate, looks at it again from within ``distance`` metres on its way, and commits
    there if the best of those views reaches the second line, ``sigma2`` (None: sigma itself). Otherwise it rejects the
    candidate, remembers the cells of its map around the goal (``CloseLook``: a later firing there is passed over),
    walks back and resumes its walk at the next frame. It leaves its walk where the policy first fires on a candidate,
    which is the candidate's own frame under any window (a later window with no new counted frame counts a subset of its
    frames), so a walk-up departs from the candidate frame's pose. Where no view came within ``distance``, the nearest
    ones stand for them (the agent got no closer); where there is no view at all (``verify`` None: a reader without the
    house, such as PIN's metrics on real photos) the candidate's own frame does. A synthetic set's walk-ups are rendered
    on demand (``navigation.walk_decisions``). Every step of the detours counts (``navigation``). Nothing of the walk
    after the frame where it commits is read, nor any view of a candidate it did not walk up to."""

    PREFIX: ClassVar[str] = "approach:"
    distance: float = field(default=1.0, kw_only=True)
    sigma2: float | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (math.isfinite(self.distance) and self.distance > 0):
            raise PolicyError(f"stop policy {self}: need a finite approach distance above 0 metres")
        if self.sigma2 is not None and not math.isfinite(self.sigma2):
            raise PolicyError(f"stop policy {self}: need a finite second line")

    def __str__(self) -> str:
        distance = repr(float(self.distance)).removesuffix(".0")
        return f"approach:{distance}{'' if self.sigma2 is None else signed_text(self.sigma2)}{window_suffix(self)}"

    @classmethod
    def parse(cls, text: str) -> ApproachVerify:
        number = r"\d*\.?\d+(?:e[+-]?\d+)?"
        found = re.fullmatch(rf"\s*approach:({number})([+-]{number})?(?:@(\d+)-of-(\d+))?\s*", text)
        if not found:
            raise PolicyError(f"stop policy {text!r}: write an approach-verify one as approach:D (walk up to a "
                              "candidate, commit where a view within D metres reaches sigma, e.g. approach:1) or "
                              "approach:D+SIGMA2 (a second line of its own, e.g. approach:1+0.6, approach:1-0.2); "
                              "optionally @K-of-N")
        k, n = parsed_window(found, 3)
        return cls(k, n, distance=float(found.group(1)),
                   sigma2=None if found.group(2) is None else float(found.group(2)))

    @property
    def one_sweep(self) -> bool:
        return False

    def why_not_one_sweep(self) -> str:
        return "an approach-verify policy"

    def describe(self) -> str:
        second = "sigma" if self.sigma2 is None else f"{self.sigma2:g}"
        return (f"{self}: at a firing at sigma it walks up to the candidate and commits where a view within "
                f"{self.distance:g} m reaches {second}; else it rejects the candidate, remembers it, walks back and "
                "walks on (every step of the detours counted)")

    def second_line(self, sigma: float) -> float:
        return sigma if self.sigma2 is None else self.sigma2

    def close_score(self, look: CloseLook, own: float) -> float:
        """The score the agent verifies a candidate on: the best view within ``distance``, else the best of the nearest
        views (it got no closer), else the candidate's own frame (``own``)."""
        if not look.views:  # None (not reached) never gets here: ``_decide`` waits for the views
            return own
        near = [score for d, score in look.views if d <= self.distance]
        closest = min(d for d, _ in look.views)
        return max(near) if near else max(score for d, score in look.views if d <= closest)

    def found(self, arr: FrameArrays, sigma: float, decisions: list[Decision] | None = None) -> np.ndarray:
        """The frame whose candidate it commits to and every firing after the commit (as ``LookFurther.found``)."""
        return committed_found(self, arr, sigma, decisions)

    def _decide(self, scores: np.ndarray, fired: np.ndarray, source: np.ndarray, bounds: tuple[int, int],
                placeable: Placeable | None, sigma: float = math.nan, verify: Verify | None = None) -> Decision:
        start, end = bounds
        first: int | None = None
        candidates: list[int] = []
        rejected: list[tuple[int, int]] = []
        remembered: set = set()
        passed, last = 0, -1
        for t in np.flatnonzero(fired[start:end]) + start:
            candidate = int(source[t])
            if candidate == last:  # this firing stands for the candidate just weighed or passed over
                continue
            last = candidate
            if placeable is not None and not placeable(candidate):
                passed += 1
                continue
            look = CloseLook(candidate) if verify is None else verify(candidate)
            if look.key in remembered:  # a thing it rejected before: not proposed again
                continue
            first = int(t) if first is None else first
            candidates.append(candidate)
            if look.views is None:  # live: the agent walks up to it now
                return Decision(first, None, None, tuple(candidates), passed, tuple(rejected), candidate)
            if self.close_score(look, float(scores[candidate])) >= self.second_line(sigma):
                return Decision(first, int(t), candidate, tuple(candidates), passed, tuple(rejected))
            rejected.append((int(t), candidate))
            remembered |= look.around or {look.key}
        return Decision(first, None, None, tuple(candidates), passed, tuple(rejected))
