"""The CSV tables of the source folders (photos.csv, rooms.csv, scans.csv, families.csv): one reader, one writer.

Every such table has a header naming its columns and one row per item; a table that cannot be
read, lacks a column or holds no row is the caller's error type naming the file, so a scan
folder says ``ScanError`` and a look-alike folder ``LookalikeError``, with the same words.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

from pin_match import atomic
from pin_match.errors import PinMatchError


def read_rows(path: Path, columns: Sequence[str], error: type[PinMatchError]) -> list[dict[str, str]]:
    """The rows of a UTF-8 CSV file whose header holds ``columns`` (others may follow), at least one of them."""
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except OSError as exc:
        raise error(f"cannot read {path}: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise error(f"{path} is not a UTF-8 CSV table: {exc}") from None
    if not rows or any(c not in rows[0] for c in columns):
        raise error(f"{path} needs a header with {list(columns)} and at least one row")
    return rows


def write_rows(path: Path, columns: Sequence[str], rows: Sequence[dict]) -> None:
    """Write ``rows`` under a header of ``columns``, atomically (a source folder is never half-written)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic.write_text(path, buf.getvalue())
