"""When an agent that watches a sequence of frames declares the target found: the stop policies.

Every policy is a ``StopPolicy``: a frame *counts* when its score reaches its line, and the
policy *fires* when at least ``k`` of the last ``n`` frames of the episode count (a window never
reaches into the previous episode). PIN's rule is 1-of-1 with the line at sigma. A
``HouseStop`` raises each frame's line to the house's own level plus a margin: the level is the
mean of the highest scores of the episode's earlier frames, the objects this agent saw in this
house before (look-alikes included), so the decision is relative to the house and causal (frame t
reads only frames before it). A ``LookFurther`` policy does not commit at its first firing: it
walks on for a window of frames, remembers every candidate it sees and commits to the best one,
because within a house the target outscores its look-alikes far more reliably than one sigma
separates them across houses.

``decide`` is what every policy answers, per episode: where the window opened, where the agent
stopped looking, which frame it committed to and the candidates it weighed (``Decision``), given
which candidates can be placed in the house (the navigation estimate says; without geometry every
one can). A window that reaches past the last frame has not closed: the agent is still looking
when the recording ends, as it would be live (``PinDetector`` runs the same ``decide`` on the walk
so far). Only ``look:rest``, the upper bound, reads where the recording ends. ``found_frames``
(the frames where the policy fires; for a look-further policy the frame it commits to and every
firing after the commit) is what PIN's metrics read (``policy_metrics``, ``carry``); ``navigation``
reads the decisions; ``episode_stops`` says per episode where the line was and why.
Definitions: docs/metrics.md, "Stop policies".
"""

from __future__ import annotations

import bisect
import math
import re
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field, replace

import numpy as np

from pin_match.errors import PinMatchError
from pin_match.evaluation.core.metrics import FrameArrays


class PolicyError(PinMatchError, ValueError):
    """A stop policy that does not make sense."""


POLICY_SYNTAX = ("K-of-N (e.g. 2-of-3), house:topT+MARGIN (e.g. house:top3+0.1), look:W[+CLEAR] / look:rest "
                 "(e.g. look:20, look:20+0.1; look:rest is the upper bound) or approach:D[+SIGMA2] (e.g. approach:1, "
                 "approach:1+0.6)")
UPPER_BOUND = " (upper bound)"  # the text of a policy that reads where the recording ends says so wherever it is shown

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

    def __post_init__(self) -> None:
        if not 1 <= self.k <= self.n:
            raise PolicyError(f"stop policy {self}: need 1 <= k <= n")

    def __str__(self) -> str:
        return f"{self.k}-of-{self.n}"

    @classmethod
    def parse(cls, text: str) -> StopPolicy:
        """A policy from its text (``str`` of a policy gives it back): ``POLICY_SYNTAX``."""
        if text.strip().startswith("house:"):
            return HouseStop.parse(text)
        if text.strip().startswith("look:"):
            return LookFurther.parse(text)
        if text.strip().startswith("approach:"):
            return ApproachVerify.parse(text)
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
        return f"house:top{self.top}{_signed(self.margin)}{_base_suffix(self)}"

    @classmethod
    def parse(cls, text: str) -> HouseStop:
        found = re.fullmatch(r"\s*house:top(\d+)([+-]\d*\.?\d+(?:e[+-]?\d+)?)(?:@(\d+)-of-(\d+))?\s*", text)
        if not found:
            raise PolicyError(f"stop policy {text!r}: write a house-relative one as house:topT+MARGIN "
                              "(e.g. house:top3+0.1, house:top1-0.05; optionally @K-of-N)")
        k, n = _base_window(found, 3)
        return cls(k, n, top=int(found.group(1)), margin=float(found.group(2)))

    def level(self, arr: FrameArrays) -> np.ndarray:
        return house_level(arr, self.top)

    def running_level(self) -> RunningLevel:
        return RunningLevel(self.top)

    def bar(self, level: np.ndarray) -> np.ndarray:
        return np.nan_to_num(level, nan=-np.inf) + self.margin


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
        clear = "" if self.clear is None else _signed(abs(self.clear))  # -0.0 is 0.0: the text has no minus
        return f"look:{window}{clear}{_base_suffix(self)}{UPPER_BOUND if self.upper_bound else ''}"

    @classmethod
    def parse(cls, text: str) -> LookFurther:
        found = re.fullmatch(r"\s*look:(\d+|rest)(?:\+(\d*\.?\d+(?:e[+-]?\d+)?))?(?:@(\d+)-of-(\d+))?"
                             rf"({re.escape(UPPER_BOUND)})?\s*", text)
        if not found or (found.group(5) and found.group(1) != "rest"):
            raise PolicyError(f"stop policy {text!r}: write a look-further one as look:W (W more frames after the "
                              "first firing, e.g. look:20), look:W+CLEAR (commit at once to a candidate that beats "
                              "every earlier frame by CLEAR, e.g. look:20+0.1) or look:rest (the whole walk, the "
                              "upper bound); optionally @K-of-N")
        k, n = _base_window(found, 3)
        window = None if found.group(1) == "rest" else int(found.group(1))
        return cls(k, n, window=window, clear=None if found.group(2) is None else float(found.group(2)))

    @property
    def upper_bound(self) -> bool:
        """Does it read where the recording ends (the rest of the walk), which no agent knows?"""
        return self.window is None

    @property
    def one_sweep(self) -> bool:
        return False

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
                return Decision(first.fired, int(firings[k]), int(seen[k]), _ints(seen[:k + 1][kept[:k + 1]]),
                                first.unplaced + int((~kept[:k]).sum()))
        unplaced = first.unplaced + int((~kept).sum())
        if last > end - 1:  # the window reaches past the walk's last frame: still looking when the walk ends
            return Decision(first.fired, None, None, _ints(seen[kept]), unplaced)
        return Decision(first.fired, last, int(seen[kept][np.argmax(scores[seen[kept]])]), _ints(seen[kept]), unplaced)


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
        return f"approach:{distance}{'' if self.sigma2 is None else _signed(self.sigma2)}{_base_suffix(self)}"

    @classmethod
    def parse(cls, text: str) -> ApproachVerify:
        number = r"\d*\.?\d+(?:e[+-]?\d+)?"
        found = re.fullmatch(rf"\s*approach:({number})([+-]{number})?(?:@(\d+)-of-(\d+))?\s*", text)
        if not found:
            raise PolicyError(f"stop policy {text!r}: write an approach-verify one as approach:D (walk up to a "
                              "candidate, commit where a view within D metres reaches sigma, e.g. approach:1) or "
                              "approach:D+SIGMA2 (a second line of its own, e.g. approach:1+0.6, approach:1-0.2); "
                              "optionally @K-of-N")
        k, n = _base_window(found, 3)
        return cls(k, n, distance=float(found.group(1)),
                   sigma2=None if found.group(2) is None else float(found.group(2)))

    @property
    def one_sweep(self) -> bool:
        return False

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


def _signed(value: float) -> str:
    """A number as a policy's text writes it: its sign, then the shortest text that reads back as the same float
    (``repr``, a whole number without its ".0"), so ``parse(str(policy)) == policy`` for every value."""
    text = repr(float(value)).removesuffix(".0")
    return text if text.startswith("-") else f"+{text}"


def _base_suffix(policy: StopPolicy) -> str:
    """The text of a policy's base window after its own (``@K-of-N``; nothing for 1-of-1)."""
    return "" if (policy.k, policy.n) == (1, 1) else f"@{policy.k}-of-{policy.n}"


def _base_window(found: re.Match, group: int) -> tuple[int, int]:
    """(k, n) of a parsed ``@K-of-N`` whose K is regex group ``group`` (1-of-1 where it is absent)."""
    return (int(found.group(group)), int(found.group(group + 1))) if found.group(group) else (1, 1)


def _ints(values: np.ndarray) -> tuple[int, ...]:
    return tuple(values.tolist())


def one_walk(scores: np.ndarray) -> FrameArrays:
    """One episode's scores alone, as an agent deciding live knows them (no labels): all ``decide`` reads."""
    n = len(scores)
    return FrameArrays(score=np.asarray(scores, np.float64), cls=np.zeros(n, np.int8), episode=np.zeros(n, np.int64),
                       seen=np.zeros(n, np.int8), seen_known=False, episode_ids=np.array(["walk"]),
                       categories=np.array([""]))


def describe(policy: StopPolicy) -> str:
    """The policy in a phrase a page or a table caption can say."""
    if isinstance(policy, LookFurther):
        window = "to the walk's end, which no agent knows" if policy.upper_bound else \
            f"{policy.window} more frames (a window that runs past the walk's end leaves it still looking)"
        clear = "" if policy.clear is None else f", committing at once to one that beats every earlier frame by " \
            f"{policy.clear:g}"
        base = "PIN's first match" if (policy.k, policy.n) == (1, 1) else f"{policy.k} of {policy.n} frames"
        return (f"{policy}: after its first firing at sigma ({base}) it looks {window}, then commits to the best "
                f"candidate{clear}")
    if isinstance(policy, ApproachVerify):
        second = "sigma" if policy.sigma2 is None else f"{policy.sigma2:g}"
        return (f"{policy}: at a firing at sigma it walks up to the candidate and commits where a view within "
                f"{policy.distance:g} m reaches {second}; else it rejects the candidate, remembers it, walks back and "
                "walks on (every step of the detours counted)")
    if policy == FIRST_MATCH:
        return "first match at sigma (1-of-1)"
    return str(policy)


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
        what = "a look-further policy" if isinstance(policy, LookFurther) else f"a window of {policy.n} frames"
        raise PolicyError(f"stop policy {policy}: {what} is not one gated score a frame")
    return np.where(arr.score >= policy.bar(policy.level(arr)), arr.score, -np.inf)


FIRST_MATCH = StopPolicy()  # PIN's own rule (1-of-1), the default of every ``policy=`` parameter
DEFAULT_POLICY = FIRST_MATCH  # what a report explains: the leave-one-set-out measurement kept PIN's rule
