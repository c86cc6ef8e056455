"""The synthetic source: PIN-like rooms rendered by ``pin_match.data.synth`` (the embedded default).

A catalogue entry only: the generator lives in ``pin_match.data.synth``, and its sizes (episodes,
objects per category, frames per episode) are options of ``pin-match synth`` and of
``pin_match.data.synth.generate``; ``build`` writes the default set of a seed.
"""

from __future__ import annotations

from pathlib import Path

from pin_match.data.frameset import FrameSet
from pin_match.data.sources.catalogue import DataSource, register


def _make(out: Path, *, variant: str, seed: int, src: Path | None, overwrite: bool) -> FrameSet:
    from pin_match.data.synth import SynthSize, generate  # pybullet loads only when a synthetic set is asked for

    return generate(out, SynthSize(seed=seed), overwrite=overwrite)


SOURCE = register(DataSource(
    name="synthetic",
    summary="PIN-like rooms with procedural objects rendered on the CPU (the default set of `pin-match synth`; "
            "docs/synthetic.md)",
    licence="rendered by pin_match (MIT); any photos it draws on are listed in docs/synthetic.md",
    variants=("default",), make=_make))
