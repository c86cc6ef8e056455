"""Static HTML pieces shared by every page pin_match writes (report, inspect, compare, index).

A page is plain HTML with its images as small files in a folder beside it, so the folder
can be copied, zipped or opened offline: no script, no server, no network. Escaping holds by
construction: every piece returns ``Markup`` (markupsafe's, the type Jinja2 uses), text and
attribute values enter only through ``Markup.format`` or ``escape``, and ``page`` escapes any
part that is a plain ``str``; a link or image path is also URL-quoted (``url``), so a name with
``#``, ``?``, ``%``, a space or a non-ASCII letter still points at its file. Numbers go through
``tables.format_value``, so "n/a" means the same here as in the Markdown and LaTeX tables.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pandas as pd
from markupsafe import Markup, escape

from pin_match import atomic
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.tables import text_rows

STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #111; background: #fff; max-width: 1400px; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
dl { display: grid; grid-template-columns: max-content auto; gap: 0.2em 1em; }
dt { font-weight: bold; } dd { margin: 0; font-family: monospace; word-break: break-all; }
.gallery { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
figure { margin: 0; border: 1px solid #ccc; padding: 0.4em; background: #f7f7f7; }
figure.hit { border-color: #0a0; } figure.miss { border-color: #c00; }
figcaption { font-size: 0.8em; max-width: 330px; overflow-wrap: anywhere; }
.refs img { margin-right: 2px; }
table.figures td, table.figures th { vertical-align: top; text-align: left; border: none; padding: 0.3em; }
.note { color: #444; font-size: 0.9em; }
.swatch { display: inline-block; width: 0.9em; height: 0.9em; vertical-align: middle; border: 1px solid #333; }
"""


def page(title: str, parts: Iterable[str | Markup]) -> str:
    """A whole HTML document; a part that is plain text (not ``Markup``) is escaped."""
    body = Markup("\n").join(escape(p) for p in parts)
    return Markup('<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n<title>{}</title>\n'
                  "<style>{}</style>\n</head>\n<body>\n<h1>{}</h1>\n{}\n</body>\n</html>\n"
                  ).format(title, Markup(STYLE), title, body)


def url(path: str) -> str:
    """A relative link with every character that means something in a URL quoted ("/" kept as the separator)."""
    return quote(path, safe="/")


def join(parts: Iterable[str | Markup]) -> Markup:
    return Markup("").join(escape(p) for p in parts)


def heading(text: str, level: int = 2, anchor: str | None = None) -> Markup:
    ident = Markup(' id="{}"').format(anchor) if anchor else ""
    return Markup("<h{}{}>{}</h{}>").format(level, ident, text, level)


def paragraph(text: str | Markup, cls: str | None = None) -> Markup:
    attr = Markup(' class="{}"').format(cls) if cls else ""
    return Markup("<p{}>{}</p>").format(attr, text)


def link(href: str, text: str) -> Markup:
    """A link to a relative path (quoted here: pass the path as it is on disk)."""
    return Markup('<a href="{}">{}</a>').format(url(href), text)


def bullets(items: Iterable[str | Markup]) -> Markup:
    return Markup("<ul>{}</ul>").format(join(Markup("<li>{}</li>").format(i) for i in items))


def definitions(pairs: Sequence[tuple[str, object]]) -> Markup:
    """A header block of name / value lines."""
    return Markup("<dl>{}</dl>").format(join(Markup("<dt>{}</dt><dd>{}</dd>").format(k, str(v)) for k, v in pairs))


def table(df: pd.DataFrame, caption: str = "") -> Markup:
    """A DataFrame as an HTML table, cells formatted like the Markdown tables (undefined: "n/a")."""
    cap = Markup("<caption>{}</caption>").format(caption) if caption else ""
    head = join(Markup("<th>{}</th>").format(str(c)) for c in [df.index.name or "", *df.columns])
    body = join(Markup("<tr>{}</tr>").format(join(Markup("<td>{}</td>").format(c) for c in row))
                for row in text_rows(df))
    return Markup("<table>{}<thead><tr>{}</tr></thead><tbody>{}</tbody></table>").format(cap, head, body)


def csv_section(path: Path, index_col: str, title: str, anchor: str, note: str,
                readable: Callable[[pd.DataFrame], pd.DataFrame]) -> list[Markup]:
    """A report page's section showing a CSV the report wrote (``readable`` gives its headers; the sigma it was read
    at, its ``sigma`` and ``sigma_source`` columns, the caption): a heading, how to read it, the table; nothing
    where the report wrote no such file."""
    if not Path(path).exists():
        return []
    df = pd.read_csv(path, index_col=index_col, keep_default_na=False, na_values=[""])
    sigma = f"sigma {df['sigma'].iloc[0]:g} ({df['sigma_source'].iloc[0]})" if "sigma" in df else ""
    return [heading(title, 2, anchor), paragraph(note, "note"), table(readable(df), sigma)]


def image(src: str, alt: str, width: int | None = None) -> Markup:
    """An image from a relative path (quoted here: pass the path as it is on disk)."""
    size = Markup(' width="{}"').format(int(width)) if width else ""
    return Markup('<img src="{}" alt="{}"{}>').format(url(src), alt, size)


def figure(images: Sequence[Markup], caption_lines: Sequence[str], cls: str | None = None) -> Markup:
    """Images side by side over a caption of several short lines."""
    attr = Markup(' class="{}"').format(cls) if cls else ""
    caption = Markup("<br>").join(escape(line) for line in caption_lines)
    return Markup("<figure{}>{}<figcaption>{}</figcaption></figure>").format(attr, join(images), caption)


def figure_table(header: Sequence[str], rows: Sequence[Sequence[Markup]]) -> Markup:
    """Figures in a table, one row per item and one column per header, so the rows line up whatever each figure's
    height (a gallery wraps and staggers them)."""
    if not rows:
        return paragraph("(none)", "note")
    head = Markup("").join(Markup("<th>{}</th>").format(h) for h in header)
    body = Markup("").join(Markup("<tr>{}</tr>").format(Markup("").join(Markup("<td>{}</td>").format(c) for c in row))
                           for row in rows)
    return Markup('<table class="figures"><thead><tr>{}</tr></thead><tbody>{}</tbody></table>').format(head, body)


def gallery(figures: Sequence[Markup]) -> Markup:
    return Markup('<div class="gallery">{}</div>').format(join(figures)) if figures else paragraph("(none)", "note")


def swatch(rgb: tuple[int, int, int], label: str) -> Markup:
    r, g, b = (int(c) for c in rgb)
    return Markup('<span class="swatch" style="background: rgb({}, {}, {})"></span> {}').format(r, g, b, label)


class AssetsError(PinMatchError, OSError):
    """The images folder beside a page could not be emptied (an earlier page's images would stay beside it)."""


class Assets:
    """The image folder beside a page: each image written once, named by a counter, linked relatively.

    The folder starts empty (an earlier page's images are removed), so it holds exactly what the page shows.
    """

    def __init__(self, page_path: Path, folder: str) -> None:
        self.page_dir = page_path.parent
        self.folder = folder
        self._names: dict[object, str] = {}
        path = self.page_dir / folder
        if path.exists() or path.is_symlink():
            try:
                shutil.rmtree(path)
            except OSError as exc:
                raise AssetsError(f"cannot empty the images folder {path} of the page {page_path} "
                                  f"({type(exc).__name__}: {exc})") from exc

    def add(self, key: object, make_rgb: Callable[[], np.ndarray], suffix: str = ".jpg") -> str:
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
