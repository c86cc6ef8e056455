"""What ``pin-match list`` shows: every registered matcher and whether it can run offline now.

Each matcher is built with its default config (which loads nothing), so what is listed is
what the instance really is: its modality may depend on the config, and a composite's
weights are those of its parts.
"""

from __future__ import annotations

import pandas as pd

from pin_match.contract.matcher import Matcher
from pin_match.contract.registry import create_matcher, list_matchers
from pin_match.errors import PinMatchError

COLUMNS = ["name", "modality", "default_sigma", "weights", "license"]


def weights_status(matcher: Matcher) -> tuple[str, str]:
    """(where the weights come from and whether they are local, their license); parts are listed by role."""
    spec = matcher.weights_spec
    if spec is not None:
        state = "available" if spec.available() else "not local, pass weights="
        return f"{spec.source} ({state})", spec.license
    if not matcher.parts():
        return "none (weight-free)", ""
    parts = [(role, part, *weights_status(part)) for role, part in matcher.parts().items()]
    return ("; ".join(f"{role} {part.display_name}: {where}" for role, part, where, _ in parts),
            "; ".join(f"{role}: {lic}" for role, _, _, lic in parts if lic))


def matcher_catalog(pattern: str = "*") -> pd.DataFrame:
    rows = []
    for name in list_matchers(pattern):
        try:
            matcher = create_matcher(name)
        except (ImportError, PinMatchError) as exc:  # a plug-in that cannot load is listed, not fatal
            rows.append(dict(name=name, modality="?", default_sigma=None, weights=f"cannot load: {exc}", license=""))
            continue
        weights, license_ = weights_status(matcher)
        rows.append(dict(name=name, modality=matcher.modality.value, default_sigma=matcher.default_sigma,
                         weights=weights, license=license_))
    return pd.DataFrame(rows, columns=COLUMNS)
