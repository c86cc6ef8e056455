"""``fusion``'s file: its format, the transforms a component's score may go through, and the checks on reading it.

The file is written by ``pin_match.fitting.fusion`` and read by the ``fusion`` matcher; the fit
sits above the matchers and imports no plug-in, so what both sides must agree on is kept here once.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from pin_match.contract import WeightsError
from pin_match.matchers.common.fitted import read_fitted_file

FUSION_FORMAT = "pin-match-fusion"
FUSION_VERSION = 1
TRANSFORMS = {"identity": lambda s: s, "log1p": lambda s: math.log1p(max(s, 0.0))}


def read_fusion(path: Path) -> dict[str, Any]:
    """The fusion file, checked: every problem is a WeightsError naming the file."""
    spec = read_fitted_file(path, "fusion", FUSION_FORMAT, FUSION_VERSION)
    components = spec.get("components")
    if not isinstance(components, list) or not components:
        raise WeightsError(f"fusion file {path}: 'components' must be a non-empty list")
    for i, c in enumerate(components):
        if not isinstance(c, dict) or not isinstance(c.get("matcher"), str) or c.get("transform") not in TRANSFORMS \
                or not isinstance(c.get("coef"), (int, float)) or not math.isfinite(c["coef"]):
            raise WeightsError(f"fusion file {path}: component {i} needs 'matcher' (a name), 'config', 'id', a finite "
                               f"'coef' and 'transform' in {sorted(TRANSFORMS)}")
    if not isinstance(spec.get("intercept"), (int, float)) or not 0 <= spec.get("points_from", -1) < len(components):
        raise WeightsError(f"fusion file {path}: needs a numeric 'intercept' and 'points_from' indexing a component")
    return spec
