"""The weighted, L2-penalised logistic regression every fit here solves, and the error a fit raises.

Both fits weigh their rows by ``pin_match.evaluation.core.labels.class_weights`` (target, same-category
look-alike and other rows alike); ``require_classes`` refuses a split that lacks a side.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import combinations

import numpy as np

from pin_match.errors import PinMatchError


class FitError(PinMatchError, ValueError):
    """A fit that cannot be made: too few classes in the split, an unknown transform or signal."""


def logistic_fit(x: np.ndarray, y: np.ndarray, w: np.ndarray, l2: float, iterations: int = 50,
                 nonnegative: Sequence[int] = ()) -> np.ndarray:
    """Weighted, L2-penalised logistic regression by Newton steps; returns (intercept, coefs...).

    Features are standardised inside, so the penalty treats a count and a cosine alike; the
    returned coefficients apply to the raw features.

    ``nonnegative`` names columns of ``x`` whose coefficient must not be negative. When the
    unconstrained fit already obeys that it is returned as is; otherwise each way of fixing some
    of those coefficients at exactly 0 is refitted on the remaining columns (an active-set search,
    2^k Newton fits for k constrained columns, tried in a fixed order) and the fit with the lowest
    penalised loss among those that obey the constraint is returned: the constrained optimum,
    as the loss is convex.
    """
    mean, std = x.mean(0), x.std(0)
    std[std == 0] = 1.0
    z = np.c_[np.ones(len(x)), (x - mean) / std]
    beta = _newton(z, y, w, l2, iterations)
    constrained = sorted({int(j) for j in nonnegative})
    if any(beta[1 + j] < 0 for j in constrained):
        best = np.inf
        for size in range(1, len(constrained) + 1):
            for fixed in combinations(constrained, size):
                free = [0] + [1 + j for j in range(x.shape[1]) if j not in fixed]
                trial = np.zeros(z.shape[1])
                trial[free] = _newton(z[:, free], y, w, l2, iterations)
                loss = _penalised_loss(z, y, w, l2, trial)
                if loss < best and all(trial[1 + j] >= 0 for j in constrained):
                    best, beta = loss, trial
    coefs = beta[1:] / std
    return np.r_[beta[0] - (coefs * mean).sum(), coefs]


def _newton(z: np.ndarray, y: np.ndarray, w: np.ndarray, l2: float, iterations: int) -> np.ndarray:
    """Newton steps from zero on standardised features ``z`` (first column the intercept's ones, not penalised)."""
    penalty = np.diag([0.0] + [l2] * (z.shape[1] - 1))
    beta = np.zeros(z.shape[1])
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-z @ beta))
        grad = z.T @ (w * (p - y)) + penalty @ beta
        hess = (z * (w * p * (1 - p))[:, None]).T @ z + penalty
        step = np.linalg.solve(hess, grad)
        beta -= step
        if np.abs(step).max() < 1e-10:
            break
    return beta


def _penalised_loss(z: np.ndarray, y: np.ndarray, w: np.ndarray, l2: float, beta: np.ndarray) -> float:
    """What ``_newton`` minimises: the weighted log loss plus l2 / 2 times the squared standardised coefficients."""
    logit = z @ beta
    return float(w @ (np.logaddexp(0.0, logit) - y * logit) + 0.5 * l2 * (beta[1:] ** 2).sum())


def require_classes(counts: dict[str, int], what: str) -> None:
    """Refuse a fit without target rows or without any row that is not the target (``counts``: per fit class)."""
    if not counts["target"] or not counts["same_category"] + counts["other"]:
        raise FitError(f"{what} needs target rows and rows without the target; got {counts}")
