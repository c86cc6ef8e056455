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
one sigma can be set on it. T-norm and S-norm also need every candidate scored against every
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
        z = (raw - self.mean) / self.std
        return 1.0 / (1.0 + np.exp(-np.clip(z, -60.0, 60.0)))
