"""Synthetic PIN-like frame-sets: procedural objects in furnished rooms, rendered on the CPU with pybullet.

See docs/synthetic.md for what is modelled and why this renderer.
"""

from pin_match.data.synth.generate import SynthSize, generate
from pin_match.data.synth.objects import CATEGORIES, SynthError

__all__ = ["CATEGORIES", "SynthError", "SynthSize", "generate"]
