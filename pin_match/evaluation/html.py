"""Static HTML pieces shared by every page pin_match writes (report, inspect, compare, index).

A page is plain HTML with its images as small files in a folder beside it, so the folder
can be copied, zipped or opened offline: no script, no server, no network. Every piece
escapes its text; numbers go through ``tables.format_value``, so "n/a" means the same here
as in the Markdown and LaTeX tables.
"""

from __future__ import annotations

import html
import os
import shutil
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.evaluation.tables import text_rows

STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #111; background: #fff; max-width: 1400px; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
dl { display: grid; grid-template-columns: max-content auto; gap: 0.2em 1em; }
dt { font-weight: bold; } dd { margin: 0; font-family: monospace; word-break: break-all; }
.gallery { display: flex; flex-wrap: wrap; gap: 1em; }
figure { margin: 0; border: 1px solid #ccc; padding: 0.4em; background: #f7f7f7; }
figure.hit { border-color: #0a0; } figure.miss { border-color: #c00; }
figcaption { font-size: 0.8em; max-width: 330px; }
.refs img { margin-right: 2px; }
.note { color: #444; font-size: 0.9em; }
.swatch { display: inline-block; width: 0.9em; height: 0.9em; vertical-align: middle; border: 1px solid #333; }
"""


def page(title: str, parts: Iterable[str]) -> str:
    """A whole HTML document from already-escaped parts."""
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n<title>{html.escape(title)}</title>\n'
            f"<style>{STYLE}</style>\n</head>\n<body>\n<h1>{html.escape(title)}</h1>\n" + "\n".join(parts)
            + "\n</body>\n</html>\n")


def heading(text: str, level: int = 2, anchor: str | None = None) -> str:
    ident = f' id="{html.escape(anchor)}"' if anchor else ""
    return f"<h{level}{ident}>{html.escape(text)}</h{level}>"


def paragraph(text: str, cls: str | None = None) -> str:
    attr = f' class="{cls}"' if cls else ""
    return f"<p{attr}>{html.escape(text)}</p>"


def link(href: str, text: str) -> str:
    return f'<a href="{html.escape(href)}">{html.escape(text)}</a>'


def definitions(pairs: Sequence[tuple[str, object]]) -> str:
    """A header block of name / value lines."""
    items = "".join(f"<dt>{html.escape(k)}</dt><dd>{html.escape(str(v))}</dd>" for k, v in pairs)
    return f"<dl>{items}</dl>"


def table(df: pd.DataFrame, caption: str = "") -> str:
    """A DataFrame as an HTML table, cells formatted like the Markdown tables (undefined: "n/a")."""
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in [df.index.name or "", *df.columns])
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in text_rows(df))
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def image(src: str, alt: str, width: int | None = None) -> str:
    size = f' width="{width}"' if width else ""
    return f'<img src="{html.escape(src)}" alt="{html.escape(alt)}"{size}>'


def figure(images: Sequence[str], caption_lines: Sequence[str], cls: str | None = None) -> str:
    """Images side by side over a caption of several short lines."""
    attr = f' class="{cls}"' if cls else ""
    caption = "<br>".join(html.escape(line) for line in caption_lines)
    return f"<figure{attr}>{''.join(images)}<figcaption>{caption}</figcaption></figure>"


def gallery(figures: Sequence[str]) -> str:
    return f'<div class="gallery">{"".join(figures)}</div>' if figures else paragraph("(none)", "note")


def swatch(rgb: tuple[int, int, int], label: str) -> str:
    return (f'<span class="swatch" style="background: rgb{rgb}"></span> {html.escape(label)}')


class Assets:
    """The image folder beside a page: each image written once, named by a counter, linked relatively.

    The folder starts empty (an earlier page's images are removed), so it holds exactly what the page shows.
    """

    def __init__(self, page_path: Path, folder: str) -> None:
        self.page_dir = page_path.parent
        self.folder = folder
        self._names: dict[object, str] = {}
        shutil.rmtree(self.page_dir / folder, ignore_errors=True)

    def add(self, key: object, make_rgb, suffix: str = ".jpg") -> str:
        """The relative src of the image under ``key``, writing ``make_rgb()`` the first time it is asked for."""
        if key not in self._names:
            name = f"{self.folder}/{len(self._names):04d}{suffix}"
            params = [1, 85] if suffix == ".jpg" else []  # cv2.IMWRITE_JPEG_QUALITY = 1
            atomic.write_image(self.page_dir / name, np.ascontiguousarray(make_rgb()), params)
            self._names[key] = name
        return self._names[key]


def relative(target: Path, start: Path) -> str:
    """A link from a page in ``start`` to ``target``, with forward slashes on every OS."""
    return Path(os.path.relpath(target, start)).as_posix()


def write_page(path: Path, title: str, parts: Iterable[str]) -> Path:
    atomic.write_text(path, page(title, parts))
    return path
