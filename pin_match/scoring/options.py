"""How a scoring run is carried out, apart from what it computes: none of it enters the matcher id or the table."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RunOptions:
    """Batch size, worker count and progress bars, grouped so every layer above scoring passes one object down.

    ``workers=None`` lets the runner choose (up to 2 decoding threads here); the table's bytes
    never depend on any of these.
    """

    batch_size: int = 8
    workers: int | None = None
    progress: bool = True


DEFAULT_RUN = RunOptions()  # the default of every ``run=`` parameter (frozen, so one shared instance is safe)
