"""When an agent that watches a sequence of frames declares the target found: the stop policies.

PIN's rule stops at the first frame at or above sigma (1-of-1); agents that confirm over
several frames stop when ``k`` of the last ``n`` frames of the episode are at or above sigma
(k-of-n). ``policies`` reads PIN's detection metrics on the frames where a policy fires,
``navigation`` what the agent does at the first of them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pin_match.errors import PinMatchError
from pin_match.evaluation.metrics import FrameArrays


class PolicyError(PinMatchError, ValueError):
    """A stop policy that does not make sense."""


@dataclass(frozen=True)
class StopPolicy:
    """Found when at least ``k`` of the last ``n`` frames (this one included) are at or above sigma."""

    k: int = 1
    n: int = 1

    def __post_init__(self) -> None:
        if not 1 <= self.k <= self.n:
            raise PolicyError(f"stop policy {self.k}-of-{self.n}: need 1 <= k <= n")

    def __str__(self) -> str:
        return f"{self.k}-of-{self.n}"

    @classmethod
    def parse(cls, text: str) -> StopPolicy:
        found = re.fullmatch(r"\s*(\d+)\s*-?of-?\s*(\d+)\s*", text)
        if not found:
            raise PolicyError(f"stop policy {text!r}: write it as K-of-N, e.g. 2-of-3")
        return cls(int(found.group(1)), int(found.group(2)))


def found_frames(arr: FrameArrays, sigma: float, policy: StopPolicy) -> np.ndarray:
    """Per frame (in ``arr``'s order): does the policy fire there? Windows never reach into another episode."""
    matched = np.r_[0, np.cumsum(arr.score >= sigma)]
    index = np.arange(len(arr.score))
    starts = np.flatnonzero(np.r_[True, np.diff(arr.episode) != 0]) if len(index) else index
    episode_start = starts[np.searchsorted(starts, index, side="right") - 1] if len(index) else index
    window_start = np.maximum(index - policy.n + 1, episode_start)
    return matched[index + 1] - matched[window_start] >= policy.k


FIRST_MATCH = StopPolicy()  # PIN's own rule (1-of-1), the default of every ``policy=`` parameter
