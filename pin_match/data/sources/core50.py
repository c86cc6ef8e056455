"""CORe50 look-alikes: real photos of hand-held household objects, five instances per category.

CORe50 (Lomonaco & Maltoni, CoRL 2017; CC BY 4.0) films 50 objects, 5 instances in each of 10
categories. 128 px crops of some of its frames, their automatic masks and 10 empty office rooms
(TUM RGB-D, CC BY 4.0) ship inside pin_match (``photo_folder.PACKAGED_SRC``, licences in its
NOTICE.md), so this set builds offline; ``prepare_core50`` writes that folder again from the public
repositories. The frame-set is the look-alike set (``pin_match.data.sources.lookalike_set``) in its
``shot`` or ``pasted`` variant (docs/lookalike-set.md).
"""

from __future__ import annotations

from pathlib import Path

from pin_match import atomic
from pin_match.data.csv_rows import write_rows
from pin_match.data.frameset import FrameSet
from pin_match.data.images import read_image
from pin_match.data.mask_check import checked_mask
from pin_match.data.sources import lookalike_set
from pin_match.data.sources.catalogue import SRC_OPTIONAL, DataSource, register
from pin_match.data.sources.photo_folder import ROOM_COLUMNS, LookalikeError
from pin_match.data.sources.prepare import add_photo, checkout_commit, object_mask, write_source_folder

# CORe50 (Lomonaco & Maltoni, CoRL 2017): objects 1-50, five instances per category in this order
CORE50_CATEGORIES = ("plug_adapter", "mobile_phone", "scissors", "light_bulb", "can", "glasses", "ball", "marker",
                     "cup", "remote_control")
CORE50_LICENCE = "CC BY 4.0 (CORe50, Lomonaco & Maltoni 2017; licence file: vlomonaco/core50 LICENSE)"
CORE50_SOURCE = "github:giacomobartoli/core50_segmentation"
TUM_LICENCE = "CC BY 4.0 (TUM RGB-D benchmark, Sturm et al. 2012; frames from fr3/long_office_household)"
TUM_SOURCE = "github:gaoxiang12/slambook2"
TUM_FRAMES = tuple(f"ch11/data/{k}.png" for k in range(1, 11))
# CORe50 photos whose automatic mask, repaired or not, passes the rules of pin_match.data.mask_check but is wrong by
# eye (every photo was looked at on a contact sheet of photo, mask outline and cut-out): prepare_core50 leaves them out
CORE50_BAD_MASKS = {
    "core50_s07_o01_007": "the mask takes the grey base only; the blue top is cut off",
    "core50_s02_o08_005": "the mask takes a dark object beside the phone",
    "core50_s06_o02_013": "the mask keeps the blurred hand (too pale for the skin rule)",
    "core50_s02_o10_012": "the mask takes the shelf bracket beside the phone",
    "core50_s03_o15_012": "the mask takes the wall between the handles and misses the handles",
    "core50_s03_o17_008": "the mask takes the sheet of paper on the wall",
    "core50_s05_o20_075": "the mask keeps the hand and arm (too pale for the skin rule)",
    "core50_s04_o24_007": "the mask keeps the fingers (redder than the skin rule)",
    "core50_s06_o25_060": "the mask keeps the hand below the can (too pale for the skin rule)",
    "core50_s06_o27_055": "the mask keeps the hand (too pale for the skin rule)",
    "core50_s03_o27_009": "the mask takes one lens and the wall, not the glasses",
    "core50_s07_o26_008": "the mask takes one lens only",
    "core50_s05_o36_007": "the mask keeps the hand and the floor",
    "core50_s05_o47_011": "the mask keeps the thumb",
    "core50_s09_o50_012": "the mask keeps the fingers",
    "core50_s04_o02_005": "the mask keeps the fingers around the adapter (one pink with it in this light)",
    "core50_s04_o28_006": "the skin repair eats the pink frame: the object's colour is in the skin box",
    "core50_s06_o45_010": "the skin repair eats the mauve mug: the object's colour is in the skin box",
    "core50_s09_o41_011": "the skin repair eats the red print of the mug",
    # found on the approach variant's contact sheet (references beside the target cut-out); still shipped, and used
    # by shot and pasted, whose published numbers were measured with them; the approach variant leaves them out
    "core50_s07_o11_004": "the mask takes the handles with the wall inside them; the blades are not in it",
    "core50_s08_o11_010": "the mask takes the blade only; the handles are cut off",
    "core50_s02_o13_008": "the mask takes a strip of the blade and the wall beside it; the handles are cut off",
    "core50_s09_o26_019": "the mask takes one lens only",
    "core50_s09_o45_008": "the mask takes the handle and a sliver of the cup only",
}


def prepare_core50(core50_repo: str | Path, rooms_repo: str | Path, out: str | Path, *,
                   overwrite: bool = False) -> Path:
    """Write a source folder from a checkout of the CORe50 sample photos and of the room photos.

    ``core50_repo``: giacomobartoli/core50_segmentation (its ``images/C_<session>_<object>_<frame>.png``,
    128 px crops centred on the object). A photo whose mask fails ``checked_mask`` after its
    repair, or is in ``CORE50_BAD_MASKS``, is left out (docs/lookalike-set.md lists them).
    ``rooms_repo``: gaoxiang12/slambook2 (``ch11/data/1..10.png``: TUM RGB-D frames). Each
    photo's and room's source records its repository's commit, and NOTICE.md attributes both
    (CC BY 4.0), through ``prepare.write_source_folder``.
    """
    core50_repo, rooms_repo = Path(core50_repo), Path(rooms_repo)
    # only the 128 px crops: in the repository's 350 px frames (training_images/) the object is small and off
    # centre, and the border-seeded mask takes the wall instead
    sources = sorted((core50_repo / "images").glob("C_*.png"))
    if not sources:
        raise LookalikeError(f"{core50_repo} holds no CORe50 photos (images/C_*.png)")
    rooms = [rooms_repo / f for f in TUM_FRAMES]
    missing = [str(p) for p in rooms if not p.is_file()]
    if missing:
        raise LookalikeError(f"room photos missing: {missing}")
    photos_from, rooms_from = _at_commit(CORE50_SOURCE, core50_repo), _at_commit(TUM_SOURCE, rooms_repo)
    return write_source_folder(out, lambda stage: _write_photos(stage, sources, core50_repo, photos_from),
                               lambda rows, room_rows: _notice(len(rows), len(room_rows), photos_from, rooms_from),
                               write_rest=lambda stage: _write_rooms(stage, rooms, rooms_repo, rooms_from),
                               overwrite=overwrite)


def _write_photos(stage: Path, sources: list[Path], core50_repo: Path, photos_from: str) -> list[dict[str, str]]:
    """Each CORe50 photo whose mask passes, with its mask, into the stage; their photos.csv rows."""
    rows = []
    for src in sources:
        _, session, obj, frame = src.stem.split("_")
        o = int(obj)
        photo_id = f"core50_s{int(session):02d}_o{o:02d}_{frame}"
        rgb = read_image(src)
        kept, _ = checked_mask(rgb, object_mask(rgb))
        if kept is None or photo_id in CORE50_BAD_MASKS:
            continue
        file, mask = add_photo(stage, photo_id, src.read_bytes(), src.suffix, kept)
        rows.append(dict(photo_id=photo_id, instance_id=f"core50_o{o:02d}",
                         category=CORE50_CATEGORIES[(o - 1) // 5], file=file, mask=mask, source=photos_from,
                         source_path=str(src.relative_to(core50_repo)), licence=CORE50_LICENCE))
    return rows


def _write_rooms(stage: Path, rooms: list[Path], rooms_repo: Path, rooms_from: str) -> list[dict[str, str]]:
    """The TUM room photos and their rooms.csv, into the stage; their rows."""
    rows = []
    for k, src in enumerate(rooms, start=1):
        file = f"rooms/tum_fr3_office_{k:02d}.png"
        atomic.write_bytes(stage / file, src.read_bytes())
        rows.append(dict(room_id=f"tum_fr3_office_{k:02d}", file=file, source=rooms_from,
                         source_path=str(src.relative_to(rooms_repo)), licence=TUM_LICENCE))
    write_rows(stage / "rooms.csv", ROOM_COLUMNS, rows)
    return rows


def _notice(n_photos: int, n_rooms: int, photos_from: str, rooms_from: str) -> str:
    return f"""# Sources and licences of these photos

- `photos/` ({n_photos} photos) and the masks made from them (`masks/`, OpenCV GrabCut seeded from the
  border, `pin_match.data.sources.prepare.object_mask`): **CORe50**, V. Lomonaco and D. Maltoni, "CORe50: a
  New Dataset and Benchmark for Continuous Object Recognition", CoRL 2017, https://vlomonaco.github.io/core50/.
  Licence: **CC BY 4.0** (the licence file of github.com/vlomonaco/core50). Taken from {photos_from}
  (`images/C_<session>_<object>_<frame>.png`); each photo's original path is in `photos.csv`. Changes: file
  names, masks added.
- `rooms/` ({n_rooms} photos): **TUM RGB-D benchmark**, J. Sturm et al., "A Benchmark for the Evaluation
  of RGB-D SLAM Systems", IROS 2012, sequence `fr3/long_office_household`. Licence: **CC BY 4.0**. Taken from
  {rooms_from} (`ch11/data/1..10.png`).
"""


def _at_commit(repo: str, checkout: Path) -> str:
    """``repo`` at the commit ``checkout`` is at (the repository alone when it is no git checkout)."""
    commit = checkout_commit(checkout)
    return f"{repo}@{commit}" if commit else repo


def _make(out: Path, *, variant: str, seed: int, src: Path | None, overwrite: bool) -> FrameSet:
    """The look-alike set; a walk variant without the photos ``CORE50_BAD_MASKS`` names (see there)."""
    leave_out = CORE50_BAD_MASKS if variant in lookalike_set.WALKS else ()
    return lookalike_set.build(out, src, variant=variant, seed=seed, overwrite=overwrite, leave_out=leave_out)


SOURCE = register(DataSource(
    name="core50",
    summary="real look-alikes shipped with pin_match: CORe50 photos of 10 categories of hand-held objects, as "
            "shot, pasted into TUM office rooms, or pasted along walks through a room (walk: in an order blind to "
            "the target, the demo's real set; approach: ending at the target, a first-match stress test; "
            "docs/lookalike-set.md)",
    licence="CC BY 4.0 (CORe50, Lomonaco & Maltoni 2017; TUM RGB-D rooms, Sturm et al. 2012)",
    variants=lookalike_set.VARIANTS, make=_make, src=SRC_OPTIONAL,
    prepare_inputs=("CORE50_REPO", "ROOMS_REPO"), make_source=prepare_core50))
