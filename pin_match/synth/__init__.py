"""Synthetic PIN-like frame-sets: procedural objects in furnished rooms, rendered on the CPU with pybullet.

See docs/synthetic.md for what is modelled and why this renderer.
"""

from pin_match.synth.generate import DEFAULTS, generate
from pin_match.synth.objects import CATEGORIES

__all__ = ["CATEGORIES", "DEFAULTS", "generate"]
