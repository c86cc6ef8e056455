"""A cohort folder from a frame-set's objects: each object's reference views on grey, one image a member.

``cohort-norm`` reads a target's score against its matcher's scores of a cohort of images of
other real instances, given as a folder of images. This writes one from any frame-set (scanned
objects rendered by ``pin-match data build gso``, a photo source), with a NOTICE.md naming each
object's source and licence as the frame-set records them, so a cohort is as traceable as the
set it came from. Choose a set whose instances differ from those of the houses the cohort will
be used in: a cohort that holds a house's own objects would foresee its look-alikes and flatter
the normalisation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.data.sources.prepare import staged_source
from pin_match.errors import PinMatchError


class CohortError(PinMatchError, ValueError):
    """A cohort that cannot be written as asked."""


GREY = 128  # the background a cut-out reference view is laid on


def on_grey(view: np.ndarray) -> np.ndarray:
    """An RGBA reference view composited on a flat grey: a cohort member is an image, as a frame is."""
    alpha = view[..., 3:4].astype(np.float32) / 255.0
    return (view[..., :3].astype(np.float32) * alpha + GREY * (1.0 - alpha)).round().astype(np.uint8)


def write_cohort(fs: FrameSet, out: str | Path, *, views: int = 1, overwrite: bool = False) -> Path:
    """Write ``views`` reference views of every object of ``fs`` into ``out`` (``<object>_v<k>.png``) and a NOTICE.md;
    nothing is left at ``out`` if it fails."""
    out = Path(out)
    if views < 1:
        raise CohortError(f"a cohort needs at least one view per object, got views={views}")
    lines = [f"# Cohort from the frame-set {fs.manifest.get('name', '')} ({fs.root}, fingerprint {fs.fingerprint})",
             "", f"Each object's first {views} reference view(s) on grey. Sources and licences, as the frame-set "
             "records them:", ""]
    with staged_source(out, overwrite) as stage:
        for obj in fs.objects.sort_values("object_id").itertuples():
            for k, view in enumerate(fs.target(obj.object_id).views[:views]):
                atomic.write_image(stage / f"{obj.object_id}_v{k}.png", on_grey(view))
            source = getattr(obj, "source", "") or "source not recorded in the frame-set"
            licence = getattr(obj, "licence", "") or "licence not recorded in the frame-set"
            lines.append(f"- {obj.object_id} ({obj.category}): {source}; {licence}")
        atomic.write_text(stage / "NOTICE.md", "\n".join(lines) + "\n")
    return out
