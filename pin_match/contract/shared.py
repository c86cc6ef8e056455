"""One computation per frame when matchers share a part: a matcher's results remembered for one pass.

``verify`` locates with an ``effnet`` map; scoring ``verify`` and ``effnet`` together would run
that network twice on every frame. Inside ``shared_pass()`` (the scoring engine opens one per
batch of frames, and one while it prepares a run's matchers for a target: variants of
``cohort-norm`` score one cohort with one base), ``Matcher.match_batch`` first looks for results
of the same matcher id, for the same target, on the very same image buffers, and computes only
on a miss. The id hashes the
config and the weights' identity, so two instances with one id compute the same numbers: a hit
returns exactly what the call would have computed, and a table scored in a group equals the
table scored alone.

Images are recognised by their buffers (address, shape, strides), not by the Python objects:
``match_batch`` hands its parts fresh views of the caller's arrays. An entry holds its images,
so no buffer it names is freed and reused while the pass lasts.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

import numpy as np

_PASS: ContextVar[dict | None] = ContextVar("pin_match_shared_pass", default=None)


@contextmanager
def shared_pass() -> Iterator[None]:
    """Remember every matcher's results until the block ends (one batch of frames of one target)."""
    token = _PASS.set({})
    try:
        yield
    finally:
        _PASS.reset(token)


def active() -> bool:
    return _PASS.get() is not None


def batch_key(matcher_id: str, target_id: str, images: Sequence[np.ndarray]) -> tuple:
    return (matcher_id, target_id, tuple((im.__array_interface__["data"][0], im.shape, im.strides) for im in images))


def recall(key: tuple) -> list[Any] | None:
    """The results remembered under ``key`` in the open pass, or None."""
    memo = _PASS.get()
    found = memo.get(key) if memo is not None else None
    return list(found[1]) if found is not None else None


def remember(key: tuple, images: Sequence[np.ndarray], results: list[Any]) -> None:
    memo = _PASS.get()
    if memo is not None:
        memo[key] = (list(images), list(results))
