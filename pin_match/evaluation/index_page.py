"""``index.html`` of a bench or demo folder: its tables and a link to every report page under it."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import pandas as pd

from pin_match.evaluation import html
from pin_match.evaluation.compare import FILES as COMPARE_FILES
from pin_match.evaluation.report_page import PAGE as REPORT_PAGE

COMPARE_PAGE = COMPARE_FILES[2]


def write_index(out: str | Path, tables: Mapping[str, pd.DataFrame], captions: Mapping[str, str]) -> Path:
    """Write ``out/index.html``: each table with its caption, then links to every report and comparison page."""
    root = Path(out)
    parts = []
    for name, joint in tables.items():
        parts += [html.heading(name), html.paragraph(captions.get(name, "")), html.table(joint)]
    pages = sorted(root.rglob(REPORT_PAGE), key=_outer_first) + sorted(root.rglob(COMPARE_PAGE), key=_outer_first)
    links = "".join(f"<li>{html.link(html.relative(p, root), html.relative(p.parent, root))}</li>" for p in pages)
    note = f"{len(pages)} pages: a report per matcher and frame-set with its galleries, then the paired comparisons."
    parts += [html.heading("Reports and comparisons"), html.paragraph(note, "note"), f"<ul>{links}</ul>"]
    return html.write_page(root / "index.html", f"pin_match results in {root}", parts)


def _outer_first(path: Path) -> tuple[int, Path]:
    """The folder's own pages before those of a set nested in it (the demo's look-alikes), in the tables' order."""
    return len(path.parts), path
