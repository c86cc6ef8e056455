"""What ``pin-match list`` shows: every registered matcher and whether it can run offline now."""

from __future__ import annotations

import pandas as pd

from pin_match.registry import get_matcher_class, list_matchers


def matcher_catalog(pattern: str = "*") -> pd.DataFrame:
    rows = []
    for name in list_matchers(pattern):
        try:
            cls = get_matcher_class(name)
        except ImportError as exc:  # a plug-in whose dependencies are missing is listed, not fatal
            rows.append(dict(name=name, modality="?", default_sigma=None, weights=f"cannot import: {exc}"))
            continue
        spec = cls.weights_spec
        if spec is None:
            weights = "none (weight-free, or a composite: see its parts)"
        else:
            weights = "cached locally" if spec.available() else f"not local (hub: {spec.hub_id}; pass weights=)"
        rows.append(dict(name=name, modality=cls.modality.value, default_sigma=cls.default_sigma, weights=weights))
    return pd.DataFrame(rows, columns=["name", "modality", "default_sigma", "weights"])

