"""Loading transformers checkpoints from a hub id or a local folder, with an error that says what to do.

Offline and not cached is the usual situation on the machines this runs on, and
transformers' own message does not mention the matcher's ``weights=`` override; every
transformers-backed matcher loads through here so that failure reads the same everywhere.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from pin_match.contract import WeightsError, WeightsSpec, misfit

T = TypeVar("T")


def load_pretrained(spec: WeightsSpec, override: str | None, who: str, load: Callable[[str], T]) -> T:
    """Call ``load(source)`` with the local override if given, else the hub id; name both on failure."""
    local = spec.local_path(override)
    source = str(local) if local is not None else spec.hub_id
    try:
        return load(source)
    except (RuntimeError, ValueError) as exc:
        if local is None:
            raise
        raise misfit(who, local, spec.hub_id, exc) from exc
    except OSError as exc:
        if local is not None:
            raise WeightsError(f"{who}: cannot load the checkpoint folder {local} ({exc})") from exc
        raise WeightsError(f"{who}: hub id {spec.hub_id!r} is neither in the local cache nor reachable "
                           f"({type(exc).__name__}); download it once, or pass weights=<folder written by "
                           "save_pretrained>") from exc
