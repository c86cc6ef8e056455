"""The synthetic source: the embedded default set, scanned look-alike families rendered by ``pin_match.data.synth``.

A catalogue entry only: the generator lives in ``pin_match.data.synth``, and its sizes (episodes,
objects per family, frames per episode) are options of ``pin-match synth`` and of
``pin_match.data.synth.generate``; ``build`` writes the default set of a seed from the scans shipped
with pin_match (the ``gso`` source renders a prepared folder of all of them).
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
    summary="the embedded default: 96 scanned real products in 17 look-alike families rendered along PIN walks on "
            "the CPU (the default set of `pin-match synth`; docs/synthetic.md)",
    licence="rendered by pin_match (MIT) from Google Scanned Objects scans, CC BY 4.0 (each named in "
            "pin_match/data/synth/gso/NOTICE.md and in the frame-set's objects.csv)",
    variants=("default",), make=_make))
