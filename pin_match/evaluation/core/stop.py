"""When an agent that watches a sequence of frames declares the target found: the stop policies.

Every policy is a ``StopPolicy``: a frame *counts* when its score reaches its line, and the
policy *fires* when at least ``k`` of the last ``n`` frames of the episode count (a window never
reaches into the previous episode). PIN's rule is 1-of-1 with the line at sigma. A
``HouseStop`` raises each frame's line to the house's own level plus a margin: the level is the
mean of the highest scores of the episode's earlier frames, the objects this agent saw in this
house before (look-alikes included), so the decision is relative to the house and causal (frame t
reads only frames before it). ``found_frames`` is the one entry point every reader uses
(``policies`` for PIN's metrics, ``navigation`` for the walk, ``carry`` across houses);
``episode_stops`` says per episode where the line was and why. Definitions: docs/metrics.md,
"Stop policies".
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from pin_match.errors import PinMatchError
from pin_match.evaluation.core.labels import CLASSES, TM
from pin_match.evaluation.core.metrics import FrameArrays


class PolicyError(PinMatchError, ValueError):
    """A stop policy that does not make sense."""


POLICY_SYNTAX = "K-of-N (e.g. 2-of-3) or house:topT+MARGIN (e.g. house:top3+0.1)"


@dataclass(frozen=True)
class StopPolicy:
    """Found when at least ``k`` of the last ``n`` frames (this one included) are at or above their line (sigma)."""

    k: int = 1
    n: int = 1

    def __post_init__(self) -> None:
        if not 1 <= self.k <= self.n:
            raise PolicyError(f"stop policy {self.k}-of-{self.n}: need 1 <= k <= n")

    def __str__(self) -> str:
        return f"{self.k}-of-{self.n}"

    @classmethod
    def parse(cls, text: str) -> StopPolicy:
        """A policy from its text (``str`` of a policy gives it back): ``POLICY_SYNTAX``."""
        if text.strip().startswith("house:"):
            return HouseStop.parse(text)
        found = re.fullmatch(r"\s*(\d+)\s*-?of-?\s*(\d+)\s*", text)
        if not found:
            raise PolicyError(f"stop policy {text!r}: write it as {POLICY_SYNTAX}")
        return cls(int(found.group(1)), int(found.group(2)))

    def level(self, arr: FrameArrays) -> np.ndarray:
        """Per frame, the house's level the policy reads (NaN: none, as for PIN's rule)."""
        return np.full(len(arr.score), np.nan)

    def bar(self, arr: FrameArrays) -> np.ndarray:
        """Per frame, the score it must reach whatever sigma is (none here: -inf); its line is the higher of the two."""
        return np.full(len(arr.score), -np.inf)

    def line(self, arr: FrameArrays, sigma: float) -> np.ndarray:
        """Per frame, the score it must reach to count: the higher of sigma and the policy's bar."""
        return np.maximum(sigma, self.bar(arr))

    def counted(self, arr: FrameArrays, sigma: float) -> np.ndarray:
        """Per frame: is its score at or above its line?"""
        return arr.score >= self.line(arr, sigma)

    def fires(self, arr: FrameArrays, sigma: float) -> np.ndarray:
        """Per frame: do at least ``k`` of the last ``n`` frames of its episode count?"""
        counted = np.r_[0, np.cumsum(self.counted(arr, sigma))]
        index = np.arange(len(arr.score))
        starts = episode_starts(arr)
        episode_start = starts[np.searchsorted(starts, index, side="right") - 1] if len(index) else index
        window_start = np.maximum(index - self.n + 1, episode_start)
        return counted[index + 1] - counted[window_start] >= self.k


@dataclass(frozen=True)
class HouseStop(StopPolicy):
    """Found where a frame's score reaches sigma and the house's level plus ``margin``: the level is the mean of the
    ``top`` highest scores of the episode's earlier frames (all of them while fewer; none at its first frame, where
    the line is sigma alone). It assumes the target is not among the frames that set the level: a walk that starts
    facing the target raises the level with the target's own scores."""

    top: int = field(default=3, kw_only=True)
    margin: float = field(default=0.0, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.top < 1 or not np.isfinite(self.margin):
            raise PolicyError(f"stop policy {self}: need top >= 1 and a finite margin")

    def __str__(self) -> str:
        window = "" if (self.k, self.n) == (1, 1) else f"@{self.k}-of-{self.n}"
        return f"house:top{self.top}{self.margin:+g}{window}"

    @classmethod
    def parse(cls, text: str) -> HouseStop:
        found = re.fullmatch(r"\s*house:top(\d+)([+-]\d*\.?\d+(?:e[+-]?\d+)?)(?:@(\d+)-of-(\d+))?\s*", text)
        if not found:
            raise PolicyError(f"stop policy {text!r}: write a house-relative one as house:topT+MARGIN "
                              "(e.g. house:top3+0.1, house:top1-0.05; optionally @K-of-N)")
        k, n = (int(found.group(3)), int(found.group(4))) if found.group(3) else (1, 1)
        return cls(k, n, top=int(found.group(1)), margin=float(found.group(2)))

    def level(self, arr: FrameArrays) -> np.ndarray:
        return house_level(arr, self.top)

    def bar(self, arr: FrameArrays) -> np.ndarray:
        return np.nan_to_num(self.level(arr), nan=-np.inf) + self.margin


def episode_starts(arr: FrameArrays) -> np.ndarray:
    """Index of each episode's first frame (``arr`` is ordered by episode and step)."""
    return np.flatnonzero(np.r_[True, np.diff(arr.episode) != 0]) if len(arr.score) else np.zeros(0, np.int64)


def house_level(arr: FrameArrays, top: int) -> np.ndarray:
    """Per frame, the mean of the ``top`` highest scores of its episode's earlier frames (all of them while fewer);
    NaN at an episode's first frame."""
    level = np.full(len(arr.score), np.nan)
    starts = episode_starts(arr)
    for start, end in zip(starts, np.r_[starts[1:], len(arr.score)]):
        scores = arr.score[start:end]
        length = end - start
        earlier = np.where(np.tri(length, k=-1, dtype=bool), scores[None, :], -np.inf)  # row t: frames before t
        best = -np.sort(-earlier, axis=1)[:, :top]
        count = np.minimum(np.arange(length), top)
        total = np.where(np.isfinite(best), best, 0.0).sum(axis=1)
        level[start:end] = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return level


def found_frames(arr: FrameArrays, sigma: float, policy: StopPolicy) -> np.ndarray:
    """Per frame (in ``arr``'s order): does the policy fire there? The one entry point of every reader."""
    return policy.fires(arr, sigma)


def gated_scores(arr: FrameArrays, policy: StopPolicy) -> np.ndarray:
    """Each frame's score where it reaches the policy's bar, -inf where it never counts: for a 1-of-1 window the
    policy fires at sigma exactly where this is at or above sigma (any finite sigma), so one sorted sweep serves
    every sigma."""
    if policy.n != 1:
        raise PolicyError(f"stop policy {policy}: a window of {policy.n} frames is not one gated score a frame")
    return np.where(arr.score >= policy.bar(arr), arr.score, -np.inf)


FIRST_MATCH = StopPolicy()  # PIN's own rule (1-of-1), the default of every ``policy=`` parameter
DEFAULT_POLICY = FIRST_MATCH  # what a report explains: the leave-one-set-out measurement kept PIN's rule


STOP_COLUMNS = ["episode_id", "first_step", "first_class", "first_score", "stop_step", "stop_class", "stop_score",
                "stop_level", "stop_line", "peak_step", "peak_score", "peak_level", "peak_offset"]


def episode_stops(arr: FrameArrays, sigma: float, policy: StopPolicy) -> pd.DataFrame:
    """Per episode (``STOP_COLUMNS``): PIN's first match at sigma (step: the frame's 0-based position in its episode,
    class, score); where the policy stopped, the house's level there (``policy.level``, NaN without one) and the line
    the frame reached; and the target's best frame: its score, the level before it and how far above it the target
    came (its offset). None where there is no such frame."""
    level, line = policy.level(arr), policy.line(arr, sigma)
    first, fired = arr.score >= sigma, found_frames(arr, sigma, policy)
    target = arr.cls == TM
    rows = []
    starts = episode_starts(arr)
    for start, end in zip(starts, np.r_[starts[1:], len(arr.score)]):
        row = dict(episode_id=str(arr.episode_ids[arr.episode[start]]))
        for name, mask in (("first", first), ("stop", fired)):
            hit = np.flatnonzero(mask[start:end])
            t = start + int(hit[0]) if hit.size else None
            row |= {f"{name}_step": None if t is None else t - start,
                    f"{name}_class": None if t is None else CLASSES[arr.cls[t]],
                    f"{name}_score": None if t is None else float(arr.score[t])}
            if name == "stop":
                row |= dict(stop_level=None if t is None else _number(level[t]),
                            stop_line=None if t is None else float(line[t]))
        seen = np.flatnonzero(target[start:end])
        t = start + int(seen[np.argmax(arr.score[start:end][seen])]) if seen.size else None
        row |= dict(peak_step=None if t is None else t - start, peak_score=None if t is None else float(arr.score[t]),
                    peak_level=None if t is None else _number(level[t]),
                    peak_offset=None if t is None else _number(arr.score[t] - level[t]))
        rows.append(row)
    return pd.DataFrame(rows, columns=STOP_COLUMNS)


def _number(value: float) -> float | None:
    return None if np.isnan(value) else float(value)
