"""Cohort score normalisation: a target's score read against what its matcher gives other real instances.

A raw score's level varies per target: a grey cat's look-alikes score higher than a yellow
backpack's, so one sigma matches look-alikes of one and misses the other. Speaker and face
verification met this decades ago and normalise against a cohort of impostors: Z-norm takes
the mean and spread of the enrolled model's scores on the cohort (Auckenthaler et al. 2000),
adaptive Z-norm only its ``k`` closest members (Sturim and Reynolds 2005). Here the target's
reference views are the enrolment and each cohort member, an image of another real instance,
is scored by the matcher prepared for the target; ``Impostors`` keeps their statistics and
``normalised`` maps a score to ``sigmoid((g(score) - mean) / std)``, ``g`` the logit for a
matcher whose score is a probability (identity otherwise), so the result is again in [0, 1] and
one sigma can be set on it. ``TargetCohort`` keeps one target's cohort (every member's score, the
scale they give, where the images are) as the notes a score table stores per target, from which
the report shows where the scale came from and any other ``k`` can be read again without a model.
T-norm and S-norm also need every candidate scored against every
cohort member, a matcher pass per member per frame, which no frame budget allows: not offered.

Pure numpy, for any matcher (``matchers/cohort_norm.py`` wraps one).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

EPS = 1e-6


def logit(p: float | np.ndarray) -> float | np.ndarray:
    """log(p / (1 - p)), p clipped to [EPS, 1 - EPS] so a probability of exactly 0 or 1 stays finite."""
    q = np.clip(p, EPS, 1.0 - EPS)
    return np.log(q / (1.0 - q))


def sigmoid(x: float | np.ndarray) -> float | np.ndarray:
    """1 / (1 + exp(-x)), the logit's inverse; x clipped to +-60 so no overflow warns."""
    return 1.0 / (1.0 + np.exp(-np.clip(x, -60.0, 60.0)))


@dataclass(frozen=True)
class Impostors:
    """The statistics of one target's cohort scores (in the logit domain when ``probability``)."""

    mean: float
    std: float
    probability: bool

    @classmethod
    def of(cls, scores: Sequence[float], *, k: int = 0, min_std: float = 0.25, probability: bool = True) -> Impostors:
        """From the matcher's scores of the cohort images: all of them (``k`` 0, Z-norm) or the ``k`` highest
        (adaptive); the spread never below ``min_std``, so a cohort that agrees closely does not blow the scale up."""
        values = np.asarray(scores, np.float64)
        if values.size == 0 or not np.isfinite(values).all():
            raise ValueError(f"cohort scores must be finite and at least one, got {values.size}")
        values = np.sort(logit(values) if probability else values)[::-1]
        if k:
            values = values[:k]
        return cls(float(values.mean()), max(float(values.std()), min_std), probability)

    def normalised(self, score: float | np.ndarray) -> float | np.ndarray:
        """The score as a z value against the cohort, squashed to [0, 1]: 0.5 is the cohort's (top-k) mean."""
        raw = logit(score) if self.probability else np.asarray(score, np.float64)
        return sigmoid((raw - self.mean) / self.std)

    def raw(self, normalised: float | np.ndarray) -> float | np.ndarray:
        """The raw score a normalised one came from (``normalised``'s inverse, so a report can show both)."""
        value = self.mean + self.std * logit(normalised)
        return sigmoid(value) if self.probability else value


@dataclass(frozen=True)
class TargetCohort:
    """One target's cohort: each member's raw score, highest first, and the scale its ``k`` closest give."""

    folder: str
    members: tuple[tuple[str, float], ...]  # (image file name, the matcher's raw score of it), highest score first
    k: int
    impostors: Impostors

    @classmethod
    def of(cls, folder: str, names: Sequence[str], scores: Sequence[float], *, k: int, min_std: float,
           probability: bool) -> TargetCohort:
        if len(names) != len(scores):
            raise ValueError(f"{len(names)} cohort names for {len(scores)} scores")
        order = np.argsort(-np.asarray(scores, np.float64), kind="stable")
        members = tuple((str(names[i]), float(scores[i])) for i in order)
        return cls(str(folder), members, k, Impostors.of(scores, k=k, min_std=min_std, probability=probability))

    @property
    def closest(self) -> tuple[tuple[str, float], ...]:
        """The members that set the scale: the ``k`` highest-scoring (all of them for ``k`` 0)."""
        return self.members[:self.k] if self.k else self.members

    @property
    def midpoint(self) -> float:
        """The raw score that maps to 0.5: the cohort's (top-k) mean, back in the score's own units."""
        return float(self.impostors.raw(0.5))

    def as_notes(self) -> dict:
        """JSON values, as ``Matcher.target_notes`` hands them to the score table."""
        imp = self.impostors
        return dict(cohort=dict(folder=self.folder, k=self.k, mean=imp.mean, std=imp.std, probability=imp.probability,
                                members=[[name, score] for name, score in self.members]))

    @classmethod
    def from_notes(cls, notes: dict) -> TargetCohort | None:
        """The cohort a table stored for a target, or None when the notes hold none (a matcher without one)."""
        if "cohort" not in notes:
            return None
        try:
            c = notes["cohort"]
            members = tuple((str(name), float(score)) for name, score in c["members"])
            return cls(str(c["folder"]), members, int(c["k"]),
                       Impostors(float(c["mean"]), float(c["std"]), bool(c["probability"])))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"damaged cohort notes ({type(exc).__name__}: {exc})") from exc
