"""Writing a source folder from a downloaded repository: the steps every such source takes once.

``open_checkout`` checks the download (the file that makes it the repository named, its
licence file) and records the commit it is at; ``write_source_folder`` writes the folder into
a hidden stage beside ``out`` (the items by the source's own function, then their index table,
the rest of the folder and a NOTICE.md attributing every item) and renames it onto ``out`` only
when all of that succeeded: the look-alike sources' photos (``photos.csv``, the empty rooms
shipped with pin_match) and the ``gso`` scans (``scans.csv``, the shipped families) alike.
``object_mask`` is the automatic mask of a photo centred on one hand-held object, used by the
sources that have no masks.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pin_match import atomic
from pin_match.data.compose import largest_piece
from pin_match.data.csv_rows import read_rows, write_rows
from pin_match.data.mask_check import skin_pixels
from pin_match.data.sources.photo_folder import (
    OPTIONAL_PHOTO_COLUMNS,
    PACKAGED_SRC,
    PHOTO_COLUMNS,
    ROOM_COLUMNS,
    LookalikeError,
)

JPEG_QUALITY = 95  # photos a source re-encodes (cropped, recoloured) are stored at this quality


@dataclass(frozen=True)
class Checkout:
    """A downloaded repository: where it is, which one (``github:owner/name``), its commit and licence text."""

    root: Path
    repo: str
    commit: str | None  # None: a copy without .git, whose commit is unknown (each NOTICE.md says so)
    licence_text: str

    @property
    def source(self) -> str:
        """What photos.csv records as each photo's source: the repository at its commit."""
        return f"{self.repo}@{self.commit}" if self.commit else self.repo


class CommitError(LookalikeError):
    """A checkout whose commit git cannot read: git is missing or its ``.git`` is damaged."""


def checkout_commit(repo: Path) -> str | None:
    """The commit a downloaded repository is at, read from its own ``.git``; None for a copy without one.

    Only the copy's own ``.git`` is asked (``git -C`` on a plain copy would report the commit of
    a repository around it). A ``.git`` that git cannot read is a ``CommitError`` naming the
    folder: a source records a commit it read, or says that it has none, never a failure as none.
    """
    git_dir = repo / ".git"
    if not git_dir.exists():
        return None
    try:
        done = subprocess.run(["git", "--git-dir", str(git_dir), "rev-parse", "--verify", "HEAD^{commit}"],
                              capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError) as exc:
        raise CommitError(f"{repo}: cannot run git to read the commit of {git_dir} ({exc}); install git, or "
                          "prepare from a copy without .git (recorded as commit unknown)") from None
    if done.returncode or not done.stdout.strip():
        raise CommitError(f"{repo}: git cannot read the commit of {git_dir}: "
                          f"{done.stderr.strip() or 'it printed nothing'}")
    return done.stdout.strip()


def open_checkout(root: str | Path, repo: str, marker: str | Path, what: str, licence_note: str) -> Checkout:
    """Check that ``root`` is a download of ``repo`` (it holds ``marker``) with a LICENSE file, and read both.

    ``what`` names the repository in the error; ``licence_note`` says why its licence must come along.
    """
    root = Path(root)
    if not (root / marker).exists():
        raise LookalikeError(f"{root} is not a {what} checkout: {root / marker} is missing")
    licence = root / "LICENSE"
    if not licence.is_file():
        raise LookalikeError(f"{licence} is missing: {licence_note}")
    return Checkout(root, repo, checkout_commit(root), licence.read_text(encoding="utf-8"))


@contextlib.contextmanager
def staged_source(out: Path, overwrite: bool) -> Iterator[Path]:
    """A hidden folder beside ``out`` to write a source folder into; it becomes ``out`` only if the block succeeds.

    A download-and-prepare step that fails half-way leaves neither a partial source nor a
    damaged earlier one behind.
    """
    if out.exists() and not overwrite:
        raise LookalikeError(f"{out} already exists: pass overwrite=True (--overwrite) to replace it")
    atomic.ensure_dir(out.parent)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        yield stage
        if out.exists():
            shutil.rmtree(out)
        os.replace(stage, out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise


def add_photo(stage: Path, photo_id: str, image: bytes | np.ndarray, suffix: str,
              mask: np.ndarray) -> tuple[str, str]:
    """Write a photo (its downloaded bytes, or an RGB array re-encoded) and its mask; their paths in the folder."""
    file, mask_file = f"photos/{photo_id}{suffix}", f"masks/{photo_id}.png"
    if isinstance(image, bytes):
        atomic.write_bytes(stage / file, image)
    else:
        atomic.write_image(stage / file, image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY] if suffix == ".jpg" else [])
    atomic.write_image(stage / mask_file, mask)
    return file, mask_file


def copy_packaged_rooms(stage: Path) -> list[dict[str, str]]:
    """Copy the empty rooms shipped with pin_match into a source folder being written; their rows."""
    rows = read_rows(PACKAGED_SRC / "rooms.csv", ROOM_COLUMNS, LookalikeError)
    for r in rows:
        atomic.write_bytes(stage / r["file"], (PACKAGED_SRC / r["file"]).read_bytes())
    write_rows(stage / "rooms.csv", ROOM_COLUMNS, rows)
    return rows


def notice(photos: str, rooms: list[dict[str, str]], licensor: str, licence_text: str) -> str:
    """A source folder's NOTICE.md: what ``photos`` says of the photos, the rooms' sources, the licence text."""
    sources = "; ".join(sorted({f"{r['licence']}, from {r['source']}" for r in rooms}))
    return f"""# Sources and licences of these photos

- {photos.strip()}
- `rooms/` ({len(rooms)} photos, copied from the look-alike source shipped with pin_match):
  {sources}; each room's path there is in `rooms.csv`.

## Licence of {licensor}

```
{licence_text.strip()}
```
"""


@dataclass(frozen=True)
class IndexTable:
    """The table listing a source folder's items: its file name, its columns, and the optional columns written when
    some row has them."""

    file: str
    columns: tuple[str, ...]
    optional: tuple[str, ...] = ()


PHOTO_INDEX = IndexTable("photos.csv", PHOTO_COLUMNS, OPTIONAL_PHOTO_COLUMNS)


def write_source_folder(out: str | Path, write_items: Callable[[Path], list[dict[str, str]]],
                        describe: Callable[[list[dict[str, str]], list[dict[str, str]]], str], *,
                        index: IndexTable = PHOTO_INDEX,
                        write_rest: Callable[[Path], list[dict[str, str]]] = copy_packaged_rooms,
                        overwrite: bool = False) -> Path:
    """Write a source folder: ``write_items(stage)`` writes the items (photos and masks) and returns their rows.

    Then the ``index`` table of those rows (``photos.csv`` by default), the rest of the folder
    (``write_rest``: the shipped rooms unless the source brings its own, or a scan folder's
    families) and ``NOTICE.md`` (``describe(rows, rest_rows)``, every item's attribution); all in
    a stage renamed onto ``out`` at the end, so a failure leaves no half-written folder.
    """
    out = Path(out)
    with staged_source(out, overwrite) as stage:
        rows = write_items(stage)
        optional = [c for c in index.optional if any(c in r for r in rows)]
        write_rows(stage / index.file, [*index.columns, *optional], rows)
        rest_rows = write_rest(stage)
        atomic.write_text(stage / "NOTICE.md", describe(rows, rest_rows))
    return out


def object_mask(rgb: np.ndarray, iterations: int = 5) -> np.ndarray:
    """An automatic mask (uint8, 255 = object) of the one object near the centre of a photo.

    Why this recipe: the photos centre one hand-held object, so GrabCut is seeded with the
    border as sure background and the middle as probable object; skin-coloured pixels
    (``pin_match.data.mask_check.skin_pixels``) start as probable background so the
    holding hand mostly drops out.
    The largest connected piece is kept and its holes filled. When GrabCut keeps nothing, the
    seed's middle minus skin is the mask. Deterministic (OpenCV's RNG seeded).
    """
    h, w = rgb.shape[:2]
    seed = np.full((h, w), cv2.GC_PR_BGD, np.uint8)
    by, bx = max(h // 10, 2), max(w // 10, 2)
    seed[by:h - by, bx:w - bx] = cv2.GC_PR_FGD
    seed[skin_pixels(rgb) & (seed == cv2.GC_PR_FGD)] = cv2.GC_PR_BGD
    edge = max(min(h, w) // 32, 1)
    seed[:edge], seed[-edge:], seed[:, :edge], seed[:, -edge:] = (cv2.GC_BGD,) * 4
    fallback = (seed == cv2.GC_PR_FGD).astype(np.uint8)
    cv2.setRNGSeed(0)
    cv2.grabCut(np.ascontiguousarray(rgb[..., ::-1]), seed, None, np.zeros((1, 65)), np.zeros((1, 65)),
                iterations, cv2.GC_INIT_WITH_MASK)
    fg = np.isin(seed, (cv2.GC_FGD, cv2.GC_PR_FGD)).astype(np.uint8)
    fg = largest_piece(cv2.morphologyEx(fg, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)))
    if not fg.any():
        fg = largest_piece(fallback)
    holes = cv2.floodFill(fg.copy() * 255, np.zeros((h + 2, w + 2), np.uint8), (0, 0), 255)[1] == 0
    return np.where((fg > 0) | holes, 255, 0).astype(np.uint8)
