"""The weighted, L2-penalised logistic regression every fit here solves, and the error a fit raises.

Both fits weigh their rows by ``pin_match.evaluation.labels.class_weights`` (target, same-category
look-alike and other rows alike); ``require_classes`` refuses a split that lacks a side.
"""

from __future__ import annotations

import numpy as np

from pin_match.errors import PinMatchError


class FitError(PinMatchError, ValueError):
    """A fit that cannot be made: too few classes in the split, an unknown transform or signal."""


def logistic_fit(x: np.ndarray, y: np.ndarray, w: np.ndarray, l2: float, iterations: int = 50) -> np.ndarray:
    """Weighted, L2-penalised logistic regression by Newton steps; returns (intercept, coefs...).

    Features are standardised inside, so the penalty treats a count and a cosine alike; the
    returned coefficients apply to the raw features.
    """
    mean, std = x.mean(0), x.std(0)
    std[std == 0] = 1.0
    z = np.c_[np.ones(len(x)), (x - mean) / std]
    penalty = np.diag([0.0] + [l2] * x.shape[1])
    beta = np.zeros(z.shape[1])
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-z @ beta))
        grad = z.T @ (w * (p - y)) + penalty @ beta
        hess = (z * (w * p * (1 - p))[:, None]).T @ z + penalty
        step = np.linalg.solve(hess, grad)
        beta -= step
        if np.abs(step).max() < 1e-10:
            break
    coefs = beta[1:] / std
    return np.r_[beta[0] - (coefs * mean).sum(), coefs]


def require_classes(counts: dict[str, int], what: str) -> None:
    """Refuse a fit without target rows or without any row that is not the target (``counts``: per fit class)."""
    if not counts["target"] or not counts["same_category"] + counts["other"]:
        raise FitError(f"{what} needs target rows and rows without the target; got {counts}")
