"""House-relative policies: a frame's line is the higher of sigma and the house's own level plus a margin."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from pin_match.evaluation.core.metrics import FrameArrays
from pin_match.evaluation.core.stop.base import PolicyError, StopPolicy, parsed_window, signed_text, window_suffix
from pin_match.evaluation.core.stop.levels import RunningLevel, house_level


@dataclass(frozen=True)
class HouseStop(StopPolicy):
    """Found where a frame's score reaches sigma and the house's level plus ``margin``: the level is the mean of the
    ``top`` highest scores of the episode's earlier frames (all of them while fewer; none at its first frame, where
    the line is sigma alone). It assumes the target is not among the frames that set the level: a walk that starts
    facing the target raises the level with the target's own scores."""

    PREFIX: ClassVar[str] = "house:"
    top: int = field(default=3, kw_only=True)
    margin: float = field(default=0.0, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.top < 1 or not np.isfinite(self.margin):
            raise PolicyError(f"stop policy {self}: need top >= 1 and a finite margin")

    def __str__(self) -> str:
        return f"house:top{self.top}{signed_text(self.margin)}{window_suffix(self)}"

    @classmethod
    def parse(cls, text: str) -> HouseStop:
        found = re.fullmatch(r"\s*house:top(\d+)([+-]\d*\.?\d+(?:e[+-]?\d+)?)(?:@(\d+)-of-(\d+))?\s*", text)
        if not found:
            raise PolicyError(f"stop policy {text!r}: write a house-relative one as house:topT+MARGIN "
                              "(e.g. house:top3+0.1, house:top1-0.05; optionally @K-of-N)")
        k, n = parsed_window(found, 3)
        return cls(k, n, top=int(found.group(1)), margin=float(found.group(2)))

    def level(self, arr: FrameArrays) -> np.ndarray:
        return house_level(arr, self.top)

    def running_level(self) -> RunningLevel:
        return RunningLevel(self.top)

    def bar(self, level: np.ndarray) -> np.ndarray:
        return np.nan_to_num(level, nan=-np.inf) + self.margin
