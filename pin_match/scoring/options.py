"""How a scoring run is carried out, apart from what it computes: none of it enters the matcher id or the table."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class RunOptions:
    """Batch size, worker count, progress bars and where the episodes run, grouped so every layer above scoring
    passes one object down.

    ``workers=None`` lets the runner choose (up to 2 decoding threads here); a ``client``
    (``distributed.Client``) scores the episodes on its Dask cluster instead (``workers`` is then
    unused). The table's bytes never depend on any of these.
    """

    batch_size: int = 8
    workers: int | None = None
    progress: bool = True
    client: Any = field(default=None, compare=False, repr=False)


DEFAULT_RUN = RunOptions()  # the default of every ``run=`` parameter (frozen, so one shared instance is safe)
