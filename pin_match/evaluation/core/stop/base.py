"""What every stop policy shares: when a frame counts and a window fires, the decision an episode gets, PIN's
first match, and the readers of a policy's frames (``found_frames``, ``gated_scores``). The kinds of policy live
beside it (``house``, ``look``, ``approach``) and register themselves by the prefix of their text; the package's
docstring says what each does.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Hashable
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from pin_match.errors import PinMatchError
from pin_match.evaluation.core.metrics import FrameArrays
from pin_match.evaluation.core.stop.levels import RunningLevel, episode_starts


class PolicyError(PinMatchError, ValueError):
    """A stop policy that does not make sense."""


POLICY_SYNTAX = ("K-of-N (e.g. 2-of-3), house:topT+MARGIN (e.g. house:top3+0.1), look:W[+CLEAR] / look:rest "
                 "(e.g. look:20, look:20+0.1; look:rest is the upper bound) or approach:D[+SIGMA2] (e.g. approach:1, "
                 "approach:1+0.6)")
UPPER_BOUND = " (upper bound)"  # the text of a policy that reads where the recording ends says so wherever it is shown

_KINDS: dict[str, type[StopPolicy]] = {}  # by the prefix of their text: filled as each kind is defined
Placeable = Callable[[int], bool]  # can the candidate of this frame (an index into the arrays) be placed?


@dataclass(frozen=True)
class CloseLook:
    """A candidate as an agent that walks up to it meets it: what it remembers of it if it rejects it (``key``: the
    cell of its own map the goal point falls in; ``around``: the cells it marks as checked, the key's alone when
    empty), so a later firing on the same thing is not proposed again, and each view on its way as (distance in
    metres from the goal point, score). No views: nothing was seen from close by, so the candidate's own frame stands
    for them; None: the agent has not reached it yet (live, or offline before its walk-up is rendered)."""

    key: Hashable
    views: tuple[tuple[float, float], ...] | None = ()
    around: frozenset = frozenset()


Verify = Callable[[int], CloseLook]  # frame i's candidate as the agent meets it when it walks up to it


@dataclass(frozen=True)
class Decision:
    """One episode under a policy, as indices into the arrays (None: it never commits). ``fired``: the first firing
    whose candidate could be placed, where the agent starts weighing candidates; ``stop``: the frame where it stops
    looking and commits (``fired`` itself for every policy but a look-further one); ``chosen``: the frame whose
    candidate it commits to (the latest counted frame of the firing window); ``candidates``: every candidate frame
    it weighed, in walk order; ``unplaced``: the distinct candidates passed over because they could not be placed,
    before the window and inside it (several firings may stand for one candidate: it is counted once). ``fired`` set
    with ``stop`` None: the window was still open when the walk ended (the agent is still looking)."""

    fired: int | None
    stop: int | None
    chosen: int | None
    candidates: tuple[int, ...] = ()
    unplaced: int = 0
    rejected: tuple[tuple[int, int], ...] = ()  # (frame it left the walk at, candidate) of each candidate an
    # approach-verify policy walked up to and rejected, in walk order
    approaching: int | None = None  # the candidate it walks up to now, not reached yet (live only)


@dataclass(frozen=True)
class StopPolicy:
    """Found when at least ``k`` of the last ``n`` frames (this one included) are at or above their line (sigma)."""

    k: int = 1
    n: int = 1
    PREFIX: ClassVar[str] = ""  # a kind's text starts with it (``parse``): each kind registers itself by it

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("PREFIX"):  # a kind of its own, not a subclass of one
            _KINDS[cls.PREFIX] = cls

    def __post_init__(self) -> None:
        if not 1 <= self.k <= self.n:
            raise PolicyError(f"stop policy {self}: need 1 <= k <= n")

    def __str__(self) -> str:
        return f"{self.k}-of-{self.n}"

    @classmethod
    def parse(cls, text: str) -> StopPolicy:
        """A policy from its text (``str`` of a policy gives it back): ``POLICY_SYNTAX``."""
        for prefix, kind in _KINDS.items():
            if text.strip().startswith(prefix):
                return kind.parse(text)
        found = re.fullmatch(r"\s*(\d+)\s*-?of-?\s*(\d+)\s*", text)
        if not found:
            raise PolicyError(f"stop policy {text!r}: write it as {POLICY_SYNTAX}")
        return cls(int(found.group(1)), int(found.group(2)))

    def level(self, arr: FrameArrays) -> np.ndarray:
        """Per frame, the house's level the policy reads (NaN: none, as for PIN's rule)."""
        return np.full(len(arr.score), np.nan)

    def running_level(self) -> RunningLevel:
        """The house's level kept step by step, for an agent that meets its walk one step at a time."""
        return RunningLevel(None)

    def bar(self, level: np.ndarray) -> np.ndarray:
        """Per frame, from its house's level (``level``), the score it must reach whatever sigma is (none here:
        -inf); its line is the higher of the two."""
        return np.full(len(level), -np.inf)

    def line(self, arr: FrameArrays, sigma: float, level: np.ndarray | None = None) -> np.ndarray:
        """Per frame, the score it must reach to count: the higher of sigma and the policy's bar. ``level``: the house's
        level per frame where the caller keeps it already (an agent, step by step); None: ``self.level(arr)``."""
        return np.maximum(sigma, self.bar(self.level(arr) if level is None else level))

    def counted(self, arr: FrameArrays, sigma: float) -> np.ndarray:
        """Per frame: is its score at or above its line?"""
        return arr.score >= self.line(arr, sigma)

    def fires(self, arr: FrameArrays, sigma: float) -> np.ndarray:
        """Per frame: do at least ``k`` of the last ``n`` frames of its episode count?"""
        return self._window_fires(arr, self.counted(arr, sigma))

    def _window_fires(self, arr: FrameArrays, counted: np.ndarray) -> np.ndarray:
        """Per frame, from the frames that count: do at least ``k`` of the last ``n`` frames of its episode?"""
        total = np.r_[0, np.cumsum(counted)]
        index = np.arange(len(arr.score))
        starts = episode_starts(arr)
        episode_start = starts[np.searchsorted(starts, index, side="right") - 1] if len(index) else index
        window_start = np.maximum(index - self.n + 1, episode_start)
        return total[index + 1] - total[window_start] >= self.k

    @property
    def one_sweep(self) -> bool:
        """Is the policy at every sigma one sorted sweep of its gated scores (``gated_scores``)? A 1-of-1 window is."""
        return self.n == 1

    def found(self, arr: FrameArrays, sigma: float, decisions: list[Decision] | None = None) -> np.ndarray:
        """Per frame: is it one PIN's metrics count as matched under the policy? Every frame where it fires.
        ``decisions``: the policy's, where the caller made them with what the house says (a policy that commits
        reads them; None: ``decide`` with every candidate placeable)."""
        return self.fires(arr, sigma)

    def decide(self, arr: FrameArrays, sigma: float, placeable: Placeable | None = None,
               level: np.ndarray | None = None, verify: Verify | None = None) -> list[Decision]:
        """One ``Decision`` per episode (in ``arr``'s order). ``placeable(i)``: can frame i's candidate be placed in
        the house (None: every one can, as without geometry)? A firing whose candidate cannot is passed over.
        ``level``: as for ``line``. ``verify(i)``: frame i's candidate seen from close by, which only an
        approach-verify policy reads (None: no views, each candidate's own frame stands for its close look). The
        frames may be a whole recording or an agent's walk so far: the decision reads nothing after the frame where it
        commits, and a window that reaches past the last frame is still open (no commit, ``fired`` set)."""
        counted = arr.score >= self.line(arr, sigma, level)
        fired = self._window_fires(arr, counted)
        source = latest_counted(arr, counted)
        return [self._decide(arr.score, fired, source, (start, end), placeable, sigma, verify)
                for start, end in episode_bounds(arr)]

    def _decide(self, scores: np.ndarray, fired: np.ndarray, source: np.ndarray, bounds: tuple[int, int],
                placeable: Placeable | None, sigma: float = math.nan, verify: Verify | None = None) -> Decision:
        """The first firing of frames ``start:end`` whose candidate can be placed; the agent commits there."""
        start, end = bounds
        passed, last_passed = 0, -1
        for t in np.flatnonzero(fired[start:end]) + start:
            candidate = int(source[t])
            if candidate == last_passed:  # this firing stands for the candidate just passed over
                continue
            if placeable is None or placeable(candidate):
                return Decision(int(t), int(t), candidate, (candidate,), passed)
            passed, last_passed = passed + 1, candidate
        return Decision(None, None, None, (), passed)

    def describe(self) -> str:
        """The policy in a phrase a page or a table caption can say."""
        return "first match at sigma (1-of-1)" if self == FIRST_MATCH else str(self)

    def why_not_one_sweep(self) -> str:
        """What keeps the policy from being one gated score a frame (``gated_scores``)."""
        return f"a window of {self.n} frames"


def committed_found(policy: StopPolicy, arr: FrameArrays, sigma: float,
                    decisions: list[Decision] | None = None) -> np.ndarray:
    """The frame a policy commits to and, as PIN's rule counts every frame where it fires, every firing after the frame
    where it committed (the candidates it passed over or rejected are not found); ``decisions`` as for ``found``."""
    fires = policy.fires(arr, sigma)
    mask = np.zeros(len(arr.score), bool)
    for (_, end), d in zip(episode_bounds(arr), decisions or policy.decide(arr, sigma)):
        if d.chosen is not None:
            mask[d.chosen] = True
            mask[d.stop + 1:end] = fires[d.stop + 1:end]  # type: ignore[operator]  # a commit has a stop
    return mask



def signed_text(value: float) -> str:
    """A number as a policy's text writes it: its sign, then the shortest text that reads back as the same float
    (``repr``, a whole number without its ".0"), so ``parse(str(policy)) == policy`` for every value."""
    text = repr(float(value)).removesuffix(".0")
    return text if text.startswith("-") else f"+{text}"


def window_suffix(policy: StopPolicy) -> str:
    """The text of a policy's base window after its own (``@K-of-N``; nothing for 1-of-1)."""
    return "" if (policy.k, policy.n) == (1, 1) else f"@{policy.k}-of-{policy.n}"


def parsed_window(found: re.Match, group: int) -> tuple[int, int]:
    """(k, n) of a parsed ``@K-of-N`` whose K is regex group ``group`` (1-of-1 where it is absent)."""
    return (int(found.group(group)), int(found.group(group + 1))) if found.group(group) else (1, 1)


def as_ints(values: np.ndarray) -> tuple[int, ...]:
    return tuple(values.tolist())


def one_walk(scores: np.ndarray) -> FrameArrays:
    """One episode's scores alone, as an agent deciding live knows them (no labels): all ``decide`` reads."""
    n = len(scores)
    return FrameArrays(score=np.asarray(scores, np.float64), cls=np.zeros(n, np.int8), episode=np.zeros(n, np.int64),
                       seen=np.zeros(n, np.int8), seen_known=False, episode_ids=np.array(["walk"]),
                       categories=np.array([""]))


def episode_bounds(arr: FrameArrays) -> list[tuple[int, int]]:
    """(first index, one past the last) of each episode of ``arr`` (ordered by episode and step)."""
    starts = episode_starts(arr)
    return [(int(a), int(b)) for a, b in zip(starts, np.r_[starts[1:], len(arr.score)])]


def latest_counted(arr: FrameArrays, counted: np.ndarray) -> np.ndarray:
    """Per frame, the index of the latest counted frame of its episode up to it (-1 where none): the candidate a
    firing window stands for, the frame its goal is placed from."""
    index = np.where(counted, np.arange(len(counted)), -1)
    out = np.full(len(counted), -1, np.int64)
    for start, end in episode_bounds(arr):
        out[start:end] = np.maximum.accumulate(index[start:end]) if end > start else index[start:end]
    return out


def found_frames(arr: FrameArrays, sigma: float, policy: StopPolicy,
                 decisions: list[Decision] | None = None) -> np.ndarray:
    """Per frame (in ``arr``'s order): is it found under the policy (``StopPolicy.found``)? What PIN's metrics read;
    ``decisions``: the policy's, made once by the caller with what the house says (``navigation.walk_decisions``)."""
    return policy.found(arr, sigma, decisions)


def fired_arrays(arr: FrameArrays, found: np.ndarray) -> FrameArrays:
    """``arr`` with each frame's score replaced by 1 where the policy found it and 0 elsewhere: every metric at 0.5
    (and every interval, ``intervals.bootstrap_ci``) then reads "matched" as "found"."""
    return replace(arr, score=found.astype(np.float64))


def gated_scores(arr: FrameArrays, policy: StopPolicy) -> np.ndarray:
    """Each frame's score where it reaches the policy's bar, -inf where it never counts: for a 1-of-1 window the
    policy fires at sigma exactly where this is at or above sigma (any finite sigma), so one sorted sweep serves
    every sigma."""
    if not policy.one_sweep:
        raise PolicyError(f"stop policy {policy}: {policy.why_not_one_sweep()} is not one gated score a frame")
    return np.where(arr.score >= policy.bar(policy.level(arr)), arr.score, -np.inf)


FIRST_MATCH = StopPolicy()  # PIN's own rule (1-of-1), the default of every ``policy=`` parameter
DEFAULT_POLICY = FIRST_MATCH  # what a report explains: the leave-one-set-out measurement kept PIN's rule
