"""The data-source catalogue: every source of frame-sets by name, one module each (``pin-match data list``).

``get(name).build(out, variant, seed)`` writes a source's frame-set; ``get(name).prepare(inputs,
out)`` first writes the source folder of a source whose photos are downloaded. The interface and
the catalogue: ``catalogue``; the look-alike sources' folder format (``photo_folder``), the steps
that write one (``prepare``) and the frame-set built from one (``lookalike_set``) are shared by
``core50``, ``grocery``, ``myvlm`` and ``twins``; ``gso`` writes a scan folder instead (through the
same ``prepare.write_source_folder``) and is the catalogue's entry for the synthetic generator
(``pin_match.data.synth``: the default set without a folder). Nothing lists the source modules: the
catalogue imports every module of this package the first time a name is asked for, and third
parties add theirs through the ``pin_match.data_sources`` entry-point group.
"""

from pin_match.data.sources.catalogue import ENTRY_POINT_GROUP, DataSource, DataSourceError, get, names, register

__all__ = ["ENTRY_POINT_GROUP", "DataSource", "DataSourceError", "get", "names", "register"]
