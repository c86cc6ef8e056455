"""Frame-sets: loading and validating them, writing them, and the sources that make them.

Sources: a PIN recording (``import_recording``), the synthetic generator (``synth``), the
recolour set (``realset``) and the real look-alike sets (``lookalikes``, ``grocery``); the
frame geometry and compositing they share live in ``compose``. Nothing here knows a matcher.
"""

from pin_match.data.frameset import FrameSet, FrameSetError
from pin_match.data.importer import import_recording
from pin_match.data.writer import FrameRecord, FrameSetWriter, encode_frame

__all__ = ["FrameRecord", "FrameSet", "FrameSetError", "FrameSetWriter", "encode_frame", "import_recording"]
