"""``verify``'s verifier file: the signals it may weigh, its format, the checks on reading it and its decision.

The file is written by ``pin_match.fitting.verifier`` and read by the ``verify`` matcher; the
fit sits above the matchers and imports no plug-in, so what both sides must agree on (the
signal names, the format and version, the colour penalty's input, the probability) is kept
here once.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from pin_match.contract import WeightsError
from pin_match.contract.cohort import sigmoid
from pin_match.matchers.common.fitted import read_fitted_file

SIGNALS = ("proto", "margin", "desc", "cycle", "color", "keypoints")
# keypoints on every candidate cost 0.4x effnet a frame and pushed verify past 2x effnet's cost (docs/performance.md):
# off by default, on with --cfg signals=... and a verifier file fitted for them
DEFAULT_SIGNALS = ("proto", "margin", "desc", "cycle", "color")
VERIFIER_FORMAT = "pin-match-verifier"
VERIFIER_VERSION = 2  # 2: the colour gate


def read_verifier(path: Path) -> dict[str, Any]:
    """The verifier file, checked (``check_verifier``): every problem is a WeightsError naming the file."""
    return check_verifier(read_fitted_file(path, "verifier", VERIFIER_FORMAT, VERIFIER_VERSION), path)


def check_verifier(spec: dict[str, Any], path: Path) -> dict[str, Any]:
    """``spec``, read from the verifier file ``path``, if its fields are whole and its colour terms never reward a
    colour mismatch; a WeightsError naming the file otherwise.

    ``verdict``'s probability cannot fall as the colour overlap rises when the colour weight
    (``coefs["color"]``) and the penalty's slope (``gate["coef"]``) are both 0 or more;
    ``fit_verifier`` never writes one below 0, and a file that has one is refused.
    """
    coefs, gate = spec.get("coefs"), spec.get("gate")
    fields_ok = isinstance(coefs, dict) and bool(coefs) and not set(coefs) - set(SIGNALS) and isinstance(gate, dict)
    numbers = [*coefs.values(), spec.get("intercept"), gate.get("floor"), gate.get("coef")] if fields_ok else []
    if not fields_ok or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in numbers) \
            or (gate["floor"] and "color" not in coefs):
        raise WeightsError(f"verifier file {path}: needs a finite 'intercept', 'coefs' {{signal: finite number}} "
                           f"over signals of {', '.join(SIGNALS)} and a 'gate' {{floor, coef}} (floor 0: none; "
                           f"above 0 only with color)")
    for name, value in (("coefs.color", coefs.get("color", 0.0)), ("gate.coef", gate["coef"])):
        if value < 0:
            raise WeightsError(f"verifier file {path}: {name} is {value}, below 0: a colour mismatch would raise the "
                               f"probability; refit it with pin_match.fitting.verifier.fit_verifier, which keeps "
                               f"both at 0 or more")
    return spec


def color_shortfall(color: float, floor: float) -> float:
    """How far a candidate's colour overlap falls below the floor (0 at or above it, -floor at overlap 0): the
    colour penalty's input, so the penalty is between -slope x floor and 0."""
    return min(color - floor, 0.0)


def verdict(spec: dict[str, Any], signals: dict[str, float]) -> float:
    """The fitted probability that a candidate with these signals is the target.

    The logit is ``intercept + sum coef x signal + gate.coef x color_shortfall(color, gate.floor)``.
    The last term, the colour penalty (the file calls it the gate), only subtracts: a candidate
    whose colour overlap falls short of the floor loses ``gate.coef`` logit per unit missing, at
    most ``gate.coef x gate.floor`` (at overlap 0), on top of the linear colour term; at or above
    the floor it adds nothing. Bounded, it is no veto: other terms larger than that bound still
    carry a candidate of the wrong colour. With ``coefs["color"]`` and ``gate.coef`` at 0 or more
    (``check_verifier``) the probability never rises as the colour overlap falls.
    """
    logit = float(spec["intercept"]) + sum(float(c) * signals[s] for s, c in spec["coefs"].items())
    gate = spec["gate"]
    if gate["floor"]:
        logit += float(gate["coef"]) * color_shortfall(signals["color"], float(gate["floor"]))
    return float(sigmoid(logit))
