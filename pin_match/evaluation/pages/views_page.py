"""The report page's section by reference view: what ``views.csv`` of a report folder holds, as a table a person reads.

Like the section by size, it shows a file the report already wrote and computes nothing; a
report of a matcher that names no views has no such file, and so no section.
"""

from __future__ import annotations

from pathlib import Path

from markupsafe import Markup

from pin_match.evaluation.core.views import NONE_NAMED, readable
from pin_match.evaluation.pages import html

NOTE = ("The matcher compared each candidate box with the target's reference views one at a time; a frame counts under "
        "the view its best box (the highest-scoring one) matched. Matched: the frames at or above sigma that show the "
        "target (TM) or only a same-category look-alike (CM). Target frames: every frame showing the target, matched "
        "or not. '{}': frames whose best box named no view, or that had no box.")


def views_section(path: Path) -> list[Markup]:
    """The section for ``ReportFiles.views`` (``path``): a heading, how to read it, the table; nothing if absent."""
    return html.csv_section(path, "view", "Which reference view matched", "views", NOTE.format(NONE_NAMED), readable)
