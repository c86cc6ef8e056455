"""The house's level a house-relative policy reads: the mean of the highest scores of an episode's earlier frames,
over a recording (``house_level``) and step by step for an agent (``RunningLevel``), summed the same way."""

from __future__ import annotations

import bisect
import math

import numpy as np

from pin_match.evaluation.core.metrics import FrameArrays


def episode_starts(arr: FrameArrays) -> np.ndarray:
    """Index of each episode's first frame (``arr`` is ordered by episode and step)."""
    if not len(arr.score):
        return np.zeros(0, np.int64)
    change = np.ones(len(arr.episode), bool)
    change[1:] = arr.episode[1:] != arr.episode[:-1]
    return np.flatnonzero(change)


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
        total = np.zeros(length)
        for column in np.where(np.isfinite(best), best, 0.0).T:  # summed highest first, as ``RunningLevel`` sums
            total = total + column
        level[start:end] = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return level


class RunningLevel:
    """``house_level`` of one walk as an agent meets it, a step at a time: it keeps the ``top`` highest scores of the
    finished steps (None: no house level, NaN throughout), so a step costs O(top) instead of reading the whole walk
    again. ``house_level`` stays the definition: this sums the same scores in the same order, and a test holds the
    two equal on long random walks."""

    def __init__(self, top: int | None) -> None:
        self.top = top
        self._best: list[float] = []  # the highest scores of the finished steps, highest first

    def add(self, score: float) -> None:
        """A step has finished with this score: the steps after it read it."""
        if self.top is not None:
            bisect.insort(self._best, float(score), key=lambda x: -x)
            del self._best[self.top:]

    @property
    def level(self) -> float:
        """The level of the next step: the mean of the kept scores (NaN before any step has finished)."""
        if not self._best:
            return math.nan
        total = 0.0
        for score in self._best:
            total = total + score
        return total / len(self._best)
