"""The files of fitted weights that ship as JSON (a ``fusion`` file, a ``verify`` verifier file): locating and reading.

Such a file holds a few numbers fitted by ``pin_match`` itself, not a network's checkpoint:
its identity is its content (a refitted file is new weights within one matcher version),
and reading it checks the format and version it declares before any matcher reads a field.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pin_match import atomic
from pin_match.contract import WeightsError, WeightsSpec, content_digest


@dataclass(frozen=True)
class FittedFileSpec(WeightsSpec):
    """A fitted JSON file: the user's, else the one shipped beside these modules.

    Its identity is the file's content even for the shipped one: a refitted file is new weights within one version.
    """

    def identity(self, override: str | None) -> dict[str, Any]:
        if override is not None:
            return super().identity(override)
        return {"file_sha256": content_digest(str(self.resolve(None).resolve()))}


def read_fitted_file(path: Path, kind: str, fmt: str, version: int) -> dict[str, Any]:
    """A fitted JSON file of format ``fmt`` and ``version``: a WeightsError naming the ``kind`` file otherwise."""
    spec = atomic.read_json(path, WeightsError, f"{kind} file")
    if not isinstance(spec, dict) or spec.get("format") != fmt or spec.get("version") != version:
        raise WeightsError(f"{kind} file {path}: not a {fmt} file of version {version}")
    return spec
