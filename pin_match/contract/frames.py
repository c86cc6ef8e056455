"""One batch of frames as several matchers see it: RGB once, and each matcher's results on it computed once.

``verify`` locates with an ``effnet`` map; scoring ``verify`` and ``effnet`` together would run
that network twice on every frame. The scoring engine therefore hands every matcher of a run
the same ``Frames`` (one per batch of an episode), and a matcher that runs another matcher on
the very frames it is given, a part, asks the batch for that part's results
(``frames.results(part)``, as hloc's matchers ask for features extracted once under their
configuration's name) instead of calling it. The batch computes them on the first request,
keeps them under the part's ``Matcher.share_key`` (its id, its device, the target it is
prepared for) and hands every asker a copy of its own. The id hashes the config and the
weights' identity, so two matchers with one key compute the same numbers: a table scored in a
group is the table scored alone.

A matcher without parts never sees any of this: its ``_match_batch`` receives the batch as a
list of RGB arrays (a list of its own, so what it does to the list stays its own).
"""

from __future__ import annotations

import copy
from collections.abc import Hashable, Iterable
from concurrent.futures import Executor
from typing import Any, Protocol

import numpy as np

from pin_match.contract.results import MatchResult


class Lendable(Protocol):
    """What a batch asks of a matcher (``contract.matcher.Matcher``, which builds batches, so it is not imported)."""

    parallel_frames: bool

    @property
    def share_key(self) -> Hashable: ...

    def match_frames(self, frames: Frames) -> list[MatchResult]: ...


def as_rgb(image: Any) -> np.ndarray:
    """A grey frame expanded to three channels, an RGBA one without its alpha, each contiguous (an RGB frame that
    is contiguous already is not copied).

    Anything else comes back as it is, for the matcher to refuse by name (``Matcher.match_frames``).
    """
    image = np.asarray(image)
    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = image[:, :, :3]
    return np.ascontiguousarray(image)


class Frames(list):
    """A batch of RGB frames and the results each matcher computed on it, lent by ``Matcher.share_key``.

    With a thread ``pool`` and ``workers`` > 1, a matcher whose ``parallel_frames`` allows it is
    computed on parts of the batch in that many threads, each part a batch of its own (so what
    it asks for there is computed on that part). Otherwise one thread uses a batch at a time.
    """

    def __init__(self, images: Iterable[Any], *, pool: Executor | None = None, workers: int = 1) -> None:
        super().__init__(as_rgb(image) for image in images)
        self._lent: dict[Hashable, list[MatchResult]] = {}
        self._pool, self._workers = pool, workers

    def results(self, matcher: Lendable) -> list[MatchResult]:
        """``matcher``'s results on these frames: computed on the first request, a copy of them on every one."""
        key = matcher.share_key
        if key not in self._lent:
            self._lent[key] = self._compute(matcher)
        return copy.deepcopy(self._lent[key])

    def for_one(self) -> Frames:
        """The same frames in a list of the caller's own, lending the same results (no frame is copied)."""
        own = Frames(self, pool=self._pool, workers=self._workers)
        own._lent = self._lent
        return own

    def _compute(self, matcher: Lendable) -> list[MatchResult]:
        n = min(self._workers, len(self))
        if self._pool is None or n < 2 or not matcher.parallel_frames:
            return matcher.match_frames(self)
        parts = [Frames(self[p[0]:p[-1] + 1]) for p in np.array_split(np.arange(len(self)), n)]
        futures = [self._pool.submit(matcher.match_frames, part) for part in parts]
        return [r for f in futures for r in f.result()]
