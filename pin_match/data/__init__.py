"""Frame-sets: the format (loading and validating, writing, reading image files) and the sources that make them.

The format: ``frameset`` (``FrameSet``), ``writer`` (``FrameSetWriter``), ``images`` (the one reader
of photos, reference views and masks), ``geometry`` (the optional camera poses, object positions and
geodesic lengths the navigation estimate needs), ``importer`` (a PIN recording into a frame-set), and
what every source that draws frames shares: ``compose`` (frame geometry, cut-outs, pasting) and
``mask_check`` (the rules a shipped cut-out passes). The sources (gso: the scans and the synthetic
generator, recolour, CORe50, grocery, MyVLM, recoloured twins) are one module each in the catalogue
``pin_match.data.sources``;
the synthetic renderer itself is ``synth/``. Nothing here knows a matcher.
"""

from pin_match.data.frameset import FrameSet, FrameSetError
from pin_match.data.importer import import_recording
from pin_match.data.writer import Frame, FrameRecord, FrameSetWriter, ImageFile, encode_frame

__all__ = ["Frame", "FrameRecord", "FrameSet", "FrameSetError", "FrameSetWriter", "ImageFile", "encode_frame",
           "import_recording"]
