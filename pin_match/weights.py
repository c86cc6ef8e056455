"""Where a matcher's weights come from, without ever touching the network to find out.

Every model-backed matcher names a hub id as its default and accepts ``weights=`` (a local
file or folder) as an override. Construction never loads anything; ``prepare`` does, so
``pin-match list`` and the registry stay instant and offline.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from pin_match.errors import PinMatchError


class WeightsError(PinMatchError, FileNotFoundError):
    pass


@dataclass(frozen=True)
class WeightsSpec:
    """The default hub location of a model and the license its weights come under."""

    hub_id: str
    filename: str | None = None  # a single file in the hub repo, when the loader needs one
    license: str = ""

    def local_path(self, override: str | None) -> Path | None:
        """The user's override, checked to exist; None means 'use the hub id'."""
        if override is None:
            return None
        path = Path(os.path.expanduser(override))
        if not path.exists():
            raise WeightsError(f"weights file or folder {path} does not exist")
        return path

    def available(self, override: str | None = None) -> bool:
        """True when loading would not need the network (a local override or a cached hub copy)."""
        if override is not None:
            return Path(os.path.expanduser(override)).exists()
        try:
            from huggingface_hub import try_to_load_from_cache
        except ImportError:
            return False
        probe = self.filename or "config.json"
        hit = try_to_load_from_cache(self.hub_id, probe)
        return isinstance(hit, str)


def misfit(who: str, source: str | os.PathLike, architecture: str, exc: BaseException) -> WeightsError:
    """The error for a checkpoint that exists but cannot be loaded into the configured model.

    Libraries report this as a wall of per-tensor size mismatches; the user needs the file,
    the architecture it was loaded into, and the first line of the library's reason.
    """
    reason = next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)
    return WeightsError(f"{who}: weights {source} do not fit {architecture} ({type(exc).__name__}: {reason})")
