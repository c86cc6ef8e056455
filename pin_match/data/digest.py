"""One digest of a set of files: what decides whether something built before can be trusted to be rebuilt here."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from pathlib import Path

from pin_match.errors import PinMatchError


class DigestError(PinMatchError, ValueError):
    """A file pattern that matches nothing: whatever reads it would fail too."""


def files_digest(values: Mapping[str, str], trees: Sequence[tuple[Path, Sequence[str]]]) -> str:
    """sha256 of ``values`` (name and text, sorted) and of every file the globs match under each root, each as its
    path relative to its root (with ``/``) and its bytes, in sorted path order: the same on every machine, wherever
    the package is installed and whatever its files' times. A glob matching no file is a ``DigestError``."""
    h = hashlib.sha256()
    for name in sorted(values):
        h.update(f"{name}={values[name]}".encode() + b"\0")
    for root, patterns in trees:
        files: dict[str, Path] = {}
        for pattern in patterns:
            found = {p.relative_to(root).as_posix(): p for p in root.glob(pattern) if p.is_file()}
            if not found:
                raise DigestError(f"{root / pattern} matches no file")
            files |= found
        for rel in sorted(files):
            h.update(rel.encode() + b"\0" + hashlib.sha256(files[rel].read_bytes()).digest())
    return h.hexdigest()[:16]
