"""Synthetic PIN-like frame-sets: real scanned objects in look-alike families, in furnished rooms, rendered on the CPU.

See docs/synthetic.md for what is modelled and why this renderer. ``generate`` is imported on first
use (PEP 562): pybullet prints a banner when it loads, which the command line's help and every
command that renders nothing should not show. Its module is ``generator``: a submodule of the function's
own name would replace the function here as soon as anything imported the submodule.
"""

from __future__ import annotations

from typing import Any

from pin_match.data.synth.objects import SynthError
from pin_match.data.synth.size import SynthSize

__all__ = ["SynthError", "SynthSize", "generate"]


def __getattr__(name: str) -> Any:
    if name == "generate":
        from pin_match.data.synth.generator import generate

        globals()["generate"] = generate  # kept: the next lookup is a plain attribute
        return generate
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
