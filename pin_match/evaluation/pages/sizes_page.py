"""The report page's section by size: what ``sizes.csv`` of a report folder holds, as a table a person reads.

Like the other sections of ``report_page``, it shows a file the report already wrote and computes
nothing; a folder written before the file existed has no section.
"""

from __future__ import annotations

from pathlib import Path

from markupsafe import Markup

from pin_match.evaluation.core.sizes import BAND_EDGES, readable
from pin_match.evaluation.pages import html

NOTE = ("Each frame is put in a band by the pixel area of the object that decides its class: the target in a target "
        "frame, the largest same-category look-alike in a look-alike frame, the largest other object in a frame "
        "showing only others (a frame showing nothing counts in 'all' only). AUROC-same: target frames against "
        "look-alike frames of the same band. TM % and CM %: of the band's matched frames, those showing the target or "
        "a look-alike; recall %: the band's target frames matched; FM-prec %: of the episodes whose first match falls "
        "in the band, those where it is the target. Best point on target %: the band's target frames whose "
        "highest-scoring point, matched or not, lies on the target's pixels. Band edges: {} px.")


def sizes_section(path: Path) -> list[Markup]:
    """The section for ``ReportFiles.sizes`` (``path``): a heading, how to read it, the table; nothing if absent."""
    return html.csv_section(path, "band", "By the objects' size", "sizes",
                            NOTE.format(", ".join(f"{edge:,}" for edge in BAND_EDGES)), readable)
