"""Write files so that a crash, a full disk or a kill never leaves a half-written one.

Every writer in pin_match goes through here: the bytes land in a temporary file in
the destination folder and are renamed over the target only once complete, so a reader
sees either the old file or the whole new one. ``read_json`` is the one reader of JSON files
(written here or by hand): every failure is the caller's error type, naming the file.
"""

from __future__ import annotations

import contextlib
import gzip
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pin_match.errors import PinMatchError


class OutputError(PinMatchError, OSError):
    """An output location cannot be written (read-only folder, full disk)."""


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
    except OSError as exc:
        raise OutputError(f"cannot write into {path.parent}: {exc.strerror or exc}") from exc
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except OSError as exc:
        tmp_path.unlink(missing_ok=True)
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def ensure_dir(path: str | os.PathLike) -> Path:
    """Create a folder for output, or fail naming it (read-only or full file systems included)."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=path, prefix=".probe.", delete=True)
        probe.close()
    except OSError as exc:
        raise OutputError(f"cannot write into {path}: {exc.strerror or exc}") from exc
    return path


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())


def write_text(path: str | os.PathLike, text: str) -> None:
    write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, obj: Any) -> None:
    write_text(path, json.dumps(obj, indent=2, sort_keys=False, default=_json_default) + "\n")


def read_json(path: str | os.PathLike, error: type[PinMatchError], what: str = "file") -> Any:
    """The JSON value in ``path`` (gzip-compressed when it ends in ``.gz``), or ``error`` naming the file.

    Every JSON file pin_match reads (its own outputs, a user's recording, a fitted file) comes through
    here, so a missing, unreadable, truncated, non-UTF-8 or non-JSON file fails the same way: one line
    saying what the file is (``what``, e.g. "thresholds file") and where, as the caller's own error type.
    """
    path = Path(path)
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt", encoding="utf-8") as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise error(f"missing {what} {path}") from None
    except (OSError, EOFError, ValueError) as exc:  # unreadable, a damaged gzip stream, not UTF-8, not JSON
        raise error(f"cannot read {what} {path} as JSON: {exc}") from exc


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def write_parquet(path: str | os.PathLike, table: Any) -> None:
    """Write a pandas DataFrame or a pyarrow Table as parquet, atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    if not isinstance(table, pa.Table):
        table = pa.Table.from_pandas(table, preserve_index=False)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def write_image(path: str | os.PathLike, image: np.ndarray, params: list[int] | None = None) -> None:
    """Encode with OpenCV (RGB/RGBA in, like the rest of pin_match) and write atomically."""
    import cv2

    path = Path(path)
    arr = image
    if arr.ndim == 3 and arr.shape[2] == 3:
        arr = cv2.cvtColor(arr, cv2.COLOR_RGB2BGR)
    elif arr.ndim == 3 and arr.shape[2] == 4:
        arr = cv2.cvtColor(arr, cv2.COLOR_RGBA2BGRA)
    ok, buf = cv2.imencode(path.suffix, arr, params or [])
    if not ok:
        raise OutputError(f"cannot encode {path}")
    write_bytes(path, buf.tobytes())
