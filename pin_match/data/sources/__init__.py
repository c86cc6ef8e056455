"""The data-source catalogue: every source of frame-sets by name, one module each (``pin-match data list``).

``get(name).build(out, variant, seed)`` writes a source's frame-set; ``get(name).prepare(inputs,
out)`` first writes the source folder of a source whose photos are downloaded. The interface and
the catalogue: ``catalogue``; the look-alike sources' folder format (``photo_folder``), the steps
that write one (``prepare``) and the frame-set built from one (``lookalike_set``) are shared by
``core50``, ``grocery``, ``myvlm`` and ``twins``; ``gso`` writes a scan folder for the synthetic
generator instead (``pin_match.data.synth.scans``). Every built-in module is imported below, so the
catalogue never depends on what else was imported first.
"""

from pin_match.data.sources import core50, grocery, gso, myvlm, recolour, synthetic, twins
from pin_match.data.sources.catalogue import DataSource, DataSourceError, get, names, register

BUILT_IN = (core50, grocery, gso, myvlm, recolour, synthetic, twins)

__all__ = ["BUILT_IN", "DataSource", "DataSourceError", "get", "names", "register"]
