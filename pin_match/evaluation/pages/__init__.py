"""What a reader sees: escaped HTML pieces, galleries, pictures, plots and the pages of a report or a frame-set.

Each page reads the numbers of ``core`` and draws them; none runs a flow. ``flows`` writes them.
"""
