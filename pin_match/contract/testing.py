"""The matcher contract as a check anyone can run on their own matcher, built-in or plug-in.

``check_matcher("my-matcher", weights=...)`` builds the matcher by name (so the registry,
entry points included, is exercised as users will), prepares a small synthetic target and
runs frames of awkward sizes through it. It asserts what every caller of a matcher relies
on: results that survive the base class's validation, determinism, a batch equal to its
frames one by one, the category hidden from non-category matchers, and a config id that
depends on the config only. pin_match's own contract test runs it over every registered
matcher; a plug-in author calls it from their test suite with whatever tiny weights their
matcher needs.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from pin_match.contract.matcher import (
    Matcher,
    MatcherError,
    MatchResult,
    Modality,
    Target,
    class_problems,
)
from pin_match.contract.registry import build_config, get_matcher_class
from pin_match.contract.results import notes_problem
from pin_match.errors import PinMatchError

FRAME_SHAPES: dict[str, tuple[int, ...]] = {
    "PIN 640x360": (640, 360, 3),
    "odd 333x517": (333, 517, 3),
    "square 200x200": (200, 200, 3),
    "grayscale 300x220": (300, 220),
}


class ContractError(PinMatchError, AssertionError):
    """A matcher breaks the contract; the message names the matcher and every broken rule."""


def contract_target(category: str = "mug") -> Target:
    """Three RGBA views of a striped red object (front, back, top) and three descriptions."""
    views = []
    for colour in ((200, 30, 30), (180, 40, 40), (210, 60, 30)):
        view = np.zeros((96, 96, 4), np.uint8)
        view[16:80, 20:76, :3] = colour
        view[40:48, 20:76, :3] = (255, 255, 0)
        view[16:80, 20:76, 3] = 255
        views.append(view)
    return Target("contract_object", category, tuple(views),
                  ("a red mug with a yellow stripe", "a red cup", "the red mug on the floor"))


def contract_frames(target: Target, seed: int = 0) -> dict[str, np.ndarray]:
    """Noise frames of several sizes with the target's front view pasted in, so there is something to find."""
    rng = np.random.default_rng(seed)
    view = target.views[0]
    h, w = view.shape[:2]
    frames = {}
    for label, shape in FRAME_SHAPES.items():
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        patch = view[..., :3] if image.ndim == 3 else view[..., :3].mean(-1).astype(np.uint8)
        alpha = view[..., 3] > 0
        image[30:30 + h, 30:30 + w][alpha] = patch[alpha]
        frames[label] = image
    return frames


def _same(a: MatchResult, b: MatchResult, tol: float) -> bool:
    return bool(np.isclose(a.score, b.score, rtol=tol, atol=tol) and a.points.shape == b.points.shape
                and np.allclose(a.points, b.points, atol=1e-3)
                and np.allclose(a.scores_of_points(), b.scores_of_points(), rtol=tol, atol=tol))


def check_matcher(name_or_class: str | type[Matcher], *, tol: float = 1e-4, **cfg: Any) -> dict[str, float]:
    """Run the contract on one matcher; returns each frame's score, raises ``ContractError`` listing what broke.

    ``cfg`` are config overrides, as for ``create_matcher`` (for instance tiny ``weights=``).
    """
    cls = get_matcher_class(name_or_class) if isinstance(name_or_class, str) else name_or_class
    who = f"matcher {name_or_class if isinstance(name_or_class, str) else cls.__name__}"
    broken: list[str] = class_problems(cls)
    if broken:  # the checks below would only repeat these as a traceback from deep inside matching
        raise ContractError(f"{who} breaks the contract: {'; '.join(broken)}")
    matcher = cls(build_config(cls, cfg))
    broken += _description_problems(matcher, cls(build_config(cls, cfg)))
    target = contract_target()
    matcher.prepare(target)
    seen = getattr(matcher, "_target", None)
    if matcher.modality is not Modality.CATEGORY and seen is not None and seen.category:
        broken.append(f"a {matcher.modality.value} matcher was shown the category label")
    scores = _batch_problems(matcher, contract_frames(target), tol, broken)
    problem = notes_problem(matcher.target_notes())
    if problem:
        broken.append(problem)
    try:
        embedding = np.asarray(matcher.embed_reference(target.views[0]))
        if embedding.ndim != 1 or not np.isfinite(embedding).all():
            broken.append(f"embed_reference returned shape {embedding.shape} or non-finite values")
    except MatcherError:
        pass  # no global embedding: allowed, the similarity analysis says so
    if broken:
        raise ContractError(f"{who} breaks the contract:\n- " + "\n- ".join(broken))
    return scores


def _description_problems(matcher: Matcher, twin: Matcher) -> list[str]:
    """What the registry and ``pin-match list`` read, and the refusal to match before ``prepare``."""
    broken = []
    if matcher.id != twin.id:
        broken.append(f"two instances of one config have different ids ({matcher.id}, {twin.id})")
    if not isinstance(matcher.modality, Modality):
        broken.append(f"modality {matcher.modality!r} is not a Modality")
    if not np.isfinite(float(matcher.default_sigma)):
        broken.append(f"default_sigma {matcher.default_sigma!r} is not finite")
    if not dataclasses.is_dataclass(matcher.cfg):
        broken.append("its Config is not a dataclass")
    try:
        matcher.match(np.zeros((64, 64, 3), np.uint8))
        broken.append("match() before prepare() did not raise MatcherError")
    except MatcherError:
        pass
    return broken


def _batch_problems(matcher: Matcher, frames: dict[str, np.ndarray], tol: float, broken: list[str]) -> dict[str, float]:
    """Each frame's score; a batch must equal its frames one at a time (the base class validates every result)."""
    scores = {}
    for (label, image), result in zip(frames.items(), matcher.match_batch(list(frames.values()))):
        scores[label] = result.score
        single = matcher.match(image)
        if not _same(single, result, tol):
            broken.append(f"{label}: a batch gives score {result.score:.6g} with {len(result.points)} points, "
                          f"the frame alone {single.score:.6g} with {len(single.points)} (not deterministic, "
                          "or batching changes results)")
    return scores
