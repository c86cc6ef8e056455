"""Find a matcher's score table for a frame-set in the score cache, so no shell glob is needed.

The cache is ``<cache>/<matcher>@<config hash>/<frame-set fingerprint>/``; the config hash
comes from the matcher built with the same overrides as ``pin-match score``, so a table of
another configuration is never picked up silently.
"""

from __future__ import annotations

from pathlib import Path

from pin_match.frameset import FrameSet
from pin_match.registry import create_matcher
from pin_match.scoretable import ScoreTableError, table_in


def find_score_table(cache: str | Path, fs: FrameSet, matcher: str, overrides: dict | None = None) -> Path:
    """The table ``pin-match score FS --matcher NAME [--cfg ...]`` wrote into ``cache``."""
    m = create_matcher(matcher, **(overrides or {}))
    cache = Path(cache)
    folder = cache / m.id / fs.fingerprint
    if folder.is_dir():
        return table_in(folder)
    others = sorted(p.parent.name for p in cache.glob(f"{m.display_name}@*/{fs.fingerprint}") if p.is_dir())
    if others:
        raise ScoreTableError(f"{cache} holds no table of {m.id} (this configuration) for frame-set {fs.root}, only "
                              f"of {', '.join(others)}: pass the same --cfg / --weights as to `pin-match score`, "
                              "or the table's path")
    raise ScoreTableError(f"{cache} holds no score table of {matcher} for frame-set {fs.root} ({fs.fingerprint}): "
                          f"run `pin-match score {fs.root} --matcher {matcher}` first (or pass --cache)")
