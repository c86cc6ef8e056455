"""The machine's load around each figure, and the rule that keeps figures from a busy machine out of the results.

A figure taken while other jobs share the cores is an upper bound nobody can compare, so
every benchmark records the 1-minute load average before and after it, and results are
written only when the load before every figure was at most ``QUIET_LOAD``.
"""

from __future__ import annotations

import os

QUIET_LOAD = 1.5


def load_1min() -> float:
    """The 1-minute load average (``os.getloadavg``), rounded for printing and JSON."""
    return round(os.getloadavg()[0], 2)


def busy_figures(loads: dict[str, dict[str, float]], limit: float = QUIET_LOAD) -> dict[str, float]:
    """The benchmarks whose load before the figure was above ``limit``: name -> load before."""
    return {name: load["before"] for name, load in loads.items() if load["before"] > limit}


def refusal(loads: dict[str, dict[str, float]], noisy: bool, limit: float = QUIET_LOAD) -> str | None:
    """Why the results must not be written (None when they may be): a busy machine, unless ``noisy``."""
    busy = busy_figures(loads, limit)
    if not busy or noisy:
        return None
    listed = ", ".join(f"{name} (load {load:.2f})" for name, load in busy.items())
    return (f"not writing --json: the 1-minute load average before {listed} was above {limit:g}, so these figures "
            f"are not from a quiet machine; stop the other jobs and rerun, or pass --noisy to write them anyway "
            f"(the file then says 'noisy': true)")
