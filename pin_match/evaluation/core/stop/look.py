"""Look-further policies: after the first firing the agent walks on for a window and commits to the best candidate."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from pin_match.evaluation.core.metrics import FrameArrays
from pin_match.evaluation.core.stop.base import (
    UPPER_BOUND,
    Decision,
    Placeable,
    PolicyError,
    StopPolicy,
    Verify,
    as_ints,
    committed_found,
    parsed_window,
    signed_text,
    window_suffix,
)


@dataclass(frozen=True)
class LookFurther(StopPolicy):
    """Look before committing: after the first firing (a frame that fires and whose candidate can be placed) the
    agent walks on for ``window`` more frames of its walk, remembers each candidate it sees (a firing frame's,
    placeable), and commits to the highest-scoring one (the first among equals) at the window's last frame, then
    walks back to it. A window that reaches past the walk's last frame has not closed there: the agent is still
    looking when the walk ends and commits to nothing, as it would live. ``window=None`` (``look:rest``) looks to the
    walk's end and commits there: it knows where the recording stops, which no agent does, so it is the upper bound
    and its text says so (``UPPER_BOUND``). With ``clear`` it commits at once to a candidate that beats every earlier
    frame of the episode by ``clear`` (the window's first candidate included). Nothing after the frame where it
    commits is read. ``window=0`` is the base rule."""

    PREFIX: ClassVar[str] = "look:"
    window: int | None = field(default=20, kw_only=True)
    clear: float | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.window is not None and self.window < 0:
            raise PolicyError(f"stop policy {self}: need a window of 0 frames or more")
        if self.clear is not None and not (math.isfinite(self.clear) and self.clear >= 0):
            raise PolicyError(f"stop policy {self}: need a finite clear margin of 0 or more")

    def __str__(self) -> str:
        window = "rest" if self.window is None else str(self.window)
        clear = "" if self.clear is None else signed_text(abs(self.clear))  # -0.0 is 0.0: the text has no minus
        return f"look:{window}{clear}{window_suffix(self)}{UPPER_BOUND if self.upper_bound else ''}"

    @classmethod
    def parse(cls, text: str) -> LookFurther:
        found = re.fullmatch(r"\s*look:(\d+|rest)(?:\+(\d*\.?\d+(?:e[+-]?\d+)?))?(?:@(\d+)-of-(\d+))?"
                             rf"({re.escape(UPPER_BOUND)})?\s*", text)
        if not found or (found.group(5) and found.group(1) != "rest"):
            raise PolicyError(f"stop policy {text!r}: write a look-further one as look:W (W more frames after the "
                              "first firing, e.g. look:20), look:W+CLEAR (commit at once to a candidate that beats "
                              "every earlier frame by CLEAR, e.g. look:20+0.1) or look:rest (the whole walk, the "
                              "upper bound); optionally @K-of-N")
        k, n = parsed_window(found, 3)
        window = None if found.group(1) == "rest" else int(found.group(1))
        return cls(k, n, window=window, clear=None if found.group(2) is None else float(found.group(2)))

    @property
    def upper_bound(self) -> bool:
        """Does it read where the recording ends (the rest of the walk), which no agent knows?"""
        return self.window is None

    @property
    def one_sweep(self) -> bool:
        return False

    def why_not_one_sweep(self) -> str:
        return "a look-further policy"

    def describe(self) -> str:
        window = "to the walk's end, which no agent knows" if self.upper_bound else \
            f"{self.window} more frames (a window that runs past the walk's end leaves it still looking)"
        clear = "" if self.clear is None else f", committing at once to one that beats every earlier frame by " \
            f"{self.clear:g}"
        base = "PIN's first match" if (self.k, self.n) == (1, 1) else f"{self.k} of {self.n} frames"
        return (f"{self}: after its first firing at sigma ({base}) it looks {window}, then commits to the best "
                f"candidate{clear}")

    def found(self, arr: FrameArrays, sigma: float, decisions: list[Decision] | None = None) -> np.ndarray:
        """The frame it commits to and, as PIN's rule counts every frame where it fires, every firing after the frame
        where it committed (the candidates it passed over are not found): ``window=0`` is the base rule exactly."""
        return committed_found(self, arr, sigma, decisions)

    def _decide(self, scores: np.ndarray, fired: np.ndarray, source: np.ndarray, bounds: tuple[int, int],
                placeable: Placeable | None, sigma: float = math.nan, verify: Verify | None = None) -> Decision:
        first = super()._decide(scores, fired, source, bounds, placeable)
        if first.fired is None:
            return first
        start, end = bounds
        last = end - 1 if self.window is None else first.fired + self.window
        firings, seen, kept = _window_candidates(fired, source, (first.fired, min(last, end - 1)), placeable)
        if self.clear is not None:
            before = np.r_[-np.inf, np.maximum.accumulate(scores[start:end])[:-1]]  # best of the earlier frames
            cleared = np.flatnonzero(kept & (scores[seen] >= before[seen - start] + self.clear))
            if cleared.size:  # it beats every earlier frame, so every earlier candidate: the best so far
                k = int(cleared[0])
                return Decision(first.fired, int(firings[k]), int(seen[k]), as_ints(seen[:k + 1][kept[:k + 1]]),
                                first.unplaced + int((~kept[:k]).sum()))
        unplaced = first.unplaced + int((~kept).sum())
        if last > end - 1:  # the window reaches past the walk's last frame: still looking when the walk ends
            return Decision(first.fired, None, None, as_ints(seen[kept]), unplaced)
        best = int(seen[kept][np.argmax(scores[seen[kept]])])
        return Decision(first.fired, last, best, as_ints(seen[kept]), unplaced)



def _window_candidates(fired: np.ndarray, source: np.ndarray, window: tuple[int, int],
                       placeable: Placeable | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The firings of frames ``window`` (first, last; both included) that each bring a new candidate, those
    candidates in walk order, and whether each can be placed (the window's first one can: it opened the window)."""
    firings = np.flatnonzero(fired[window[0]:window[1] + 1]) + window[0]
    seen = source[firings]  # non-decreasing: a candidate several firings stand for is one run
    new = np.ones(len(seen), bool)
    new[1:] = seen[1:] != seen[:-1]
    firings, seen = firings[new], seen[new]
    kept = np.array([placeable is None or placeable(int(c)) for c in seen], bool)
    return firings, seen, kept
