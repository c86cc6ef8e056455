"""Frame-sets: recorded observation frames with exact ground truth, the unit of offline benchmarking.

A frame-set directory keeps the target objects in PInNED's own layout (so a real PInNED
objects folder can be pointed at) and adds the frames a robot saw, each with its
per-pixel instance mask and the visibility table derived from it. The on-disk format is
documented in docs/frameset.md; ``FORMAT_VERSION`` is bumped on every incompatible change.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.contract.matcher import N_DESCRIPTIONS, N_VIEWS, Target, TargetError
from pin_match.data.geometry import Geometry, missing_reason, read_geometry
from pin_match.data.images import read_image, read_label_png
from pin_match.errors import PinMatchError

FORMAT_NAME = "pin-match-frameset"
FORMAT_VERSION = 1
ROLES = ("target", "same_category", "other")
SPLITS = ("train", "val")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")

MANIFEST = "frameset.json"
OBJECTS = "objects.csv"
DESCRIPTIONS = "objects_descriptions.json"
OBJECT_IMAGES = "objects_images"
EPISODES = "episodes.json"
FRAMES = "frames.parquet"
VISIBILITY = "visibility.parquet"


class FrameSetError(PinMatchError, ValueError):
    """A frame-set on disk is missing something or contradicts itself."""


def view_files(object_dir: Path) -> list[Path]:
    """The reference views of one object, in view order (PInNED names them <id>_<k>.png)."""
    return sorted(p for p in object_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)


@dataclass(eq=False, repr=False)
class FrameSet:
    """A validated frame-set: pandas tables in memory, images read lazily (``load`` builds one)."""

    root: Path
    manifest: dict
    objects: pd.DataFrame
    descriptions: dict
    episodes: pd.DataFrame
    episode_records: list[dict]
    frames: pd.DataFrame
    visibility: pd.DataFrame
    geometry: Geometry | None = None  # camera poses, object positions, geodesic lengths (``data.geometry``)
    split_name: str | None = None  # a view of one split (``split``) keeps the whole set's fingerprint

    def __post_init__(self) -> None:
        self._frame_index = self.frames.set_index("frame_id")

    # ----------------------------------------------------------------- loading
    @classmethod
    def load(cls, path: str | Path) -> FrameSet:
        root = Path(path)
        if not root.is_dir():
            raise FrameSetError(f"frame-set folder {root} does not exist")
        manifest = _read_json(root / MANIFEST)
        if manifest.get("format") != FORMAT_NAME:
            raise FrameSetError(f"{root / MANIFEST} is not a {FORMAT_NAME} manifest")
        version = manifest.get("version")
        if not isinstance(version, int) or version > FORMAT_VERSION:
            raise FrameSetError(
                f"{root / MANIFEST} has format version {version}; this pin_match reads up to "
                f"version {FORMAT_VERSION}: upgrade pin_match"
            )
        objects = _read_table(root / OBJECTS, ["object_id", "category", "split"])
        objects["object_id"] = objects["object_id"].astype(str)
        descriptions = _read_json(root / DESCRIPTIONS)
        _check_objects(root, objects, descriptions)
        records = _read_json(root / EPISODES).get("episodes")
        if not isinstance(records, list):
            raise FrameSetError(f"{root / EPISODES} must hold {{'episodes': [...]}}")
        episodes = _episodes_table(root, records, objects)
        frames = _read_table(root / FRAMES, ["frame_id", "episode_id", "step", "image", "mask"])
        _check_frames(root, frames, episodes)
        _check_approach_views(root, frames, episodes)
        frames = frames.merge(episodes[["episode_id", "split"]], on="episode_id", how="left")
        visibility = _read_table(root / VISIBILITY,
                                 ["frame_id", "object_id", "role", "mask_value", "pixels", "x0", "y0", "x1", "y1"])
        _check_visibility(root, visibility, frames, objects)
        geometry = read_geometry(root, manifest, frames, records)
        return cls(root, manifest, objects, descriptions, episodes, records, frames, visibility, geometry)

    # ----------------------------------------------------------------- access
    def _frame(self, frame_id: str) -> pd.Series:
        try:
            return self._frame_index.loc[frame_id]
        except KeyError:
            raise FrameSetError(f"unknown frame id {frame_id!r} in {self.root}") from None

    def image(self, frame_id: str) -> np.ndarray:
        """The RGB observation, H x W x 3 uint8."""
        return read_image(self.root / self._frame(frame_id)["image"])

    def instance_mask(self, frame_id: str) -> np.ndarray:
        """Per-pixel ``mask_value`` ids (0 = background); see ``visibility.mask_value``."""
        return read_label_png(self.root / self._frame(frame_id)["mask"])

    def depth(self, frame_id: str) -> np.ndarray:
        """Depth in metres (float32), 0 where nothing was hit."""
        row = self._frame(frame_id)
        if "depth" not in row or not isinstance(row["depth"], str):
            raise FrameSetError(f"frame {frame_id!r} has no depth recorded")
        return read_label_png(self.root / row["depth"]).astype(np.float32) / 1000.0

    def object_pixels(self, frame_id: str, object_id: str) -> np.ndarray:
        """Boolean mask of one visible object in one frame (all False when not visible)."""
        mask = self.instance_mask(frame_id)
        rows = self.visibility[(self.visibility.frame_id == frame_id) & (self.visibility.object_id == object_id)]
        if rows.empty:
            return np.zeros(mask.shape, bool)
        return mask == int(rows.iloc[0]["mask_value"])

    def target(self, object_id: str) -> Target:
        """The 3 RGBA views, 3 descriptions and category of one object."""
        obj = self.objects[self.objects.object_id == object_id]
        if obj.empty:
            raise FrameSetError(f"unknown object id {object_id!r} in {self.root / OBJECTS}")
        paths = view_files(self.root / OBJECT_IMAGES / object_id)
        views = tuple(read_image(p, rgba=True) for p in paths)
        try:
            return Target(object_id=object_id, category=str(obj.iloc[0]["category"]), views=views,
                          descriptions=tuple(self.descriptions[object_id]),
                          view_paths=tuple(str(p) for p in paths))
        except TargetError as exc:
            raise FrameSetError(f"{self.root}: {exc}") from exc

    def episode(self, episode_id: str) -> pd.Series:
        rows = self.episodes[self.episodes.episode_id == episode_id]
        if rows.empty:
            raise FrameSetError(f"unknown episode id {episode_id!r} in {self.root / EPISODES}")
        return rows.iloc[0]

    def split(self, split: str | None) -> FrameSet:
        """A view restricted to one split (None or 'all' keeps everything)."""
        if split in (None, "all"):
            return self
        if split not in set(self.episodes.split):
            raise FrameSetError(f"split {split!r} not in {self.root} (has {sorted(set(self.episodes.split))})")
        episodes = self.episodes[self.episodes.split == split].reset_index(drop=True)
        frames = self.frames[self.frames.split == split].reset_index(drop=True)
        visibility = self.visibility[self.visibility.frame_id.isin(frames.frame_id)].reset_index(drop=True)
        records = [r for r in self.episode_records if r["episode_id"] in set(episodes.episode_id)]
        sub = FrameSet(self.root, self.manifest, self.objects, self.descriptions, episodes, records, frames,
                       visibility, self.geometry, split)
        sub.__dict__["fingerprint"] = self.fingerprint
        return sub

    @property
    def approach_views(self) -> pd.DataFrame:
        """The frames an agent meets walking up to an object to check it (``approach_of``: the object,
        ``approach_distance``: horizontal metres to its centre), not frames of the walk; empty where the set has
        none (docs/frameset.md, "Approach views")."""
        if "approach_of" not in self.frames.columns:
            return self.frames.iloc[:0]
        return self.frames[self.frames.approach_of.notna()]

    @property
    def navigation_missing(self) -> str | None:
        """Why PIN's navigation metrics cannot be estimated on this frame-set (None when they can)."""
        return missing_reason(self.manifest, self.frames)

    @cached_property
    def fingerprint(self) -> str:
        """Content hash of the whole frame-set: tables, descriptions, references and frame checksums."""
        h = hashlib.sha256()
        for name in (MANIFEST, OBJECTS, DESCRIPTIONS, EPISODES, VISIBILITY):
            h.update(name.encode())
            h.update((self.root / name).read_bytes())
        frame_cols = [c for c in ("frame_id", "episode_id", "step", "sha256", "approach_of", "approach_distance")
                      if c in self.frames.columns]
        h.update(pd.util.hash_pandas_object(self.frames[frame_cols], index=False).values.tobytes())
        for object_id in sorted(self.objects.object_id):
            for p in view_files(self.root / OBJECT_IMAGES / object_id):
                h.update(hashlib.sha256(p.read_bytes()).digest())
        for record in self.episode_records:  # floor maps, where the producer stored them (a set without keeps its hash)
            if "floor_map" in record:
                h.update(hashlib.sha256((self.root / str(record["floor_map"]["file"])).read_bytes()).digest())
        return h.hexdigest()[:16]

    def __repr__(self) -> str:
        return (f"FrameSet({str(self.root)!r}, objects={len(self.objects)}, episodes={len(self.episodes)}, "
                f"frames={len(self.frames)})")


# ------------------------------------------------------------------ validation helpers
def _read_json(path: Path) -> dict:
    data = atomic.read_json(path, FrameSetError)  # a missing one: "missing file PATH"
    if not isinstance(data, dict):
        raise FrameSetError(f"{path} must hold a JSON object, not {type(data).__name__}")
    return data


def _read_table(path: Path, required: list[str]) -> pd.DataFrame:
    if not path.exists():
        raise FrameSetError(f"missing file {path}")
    try:
        if path.suffix == ".parquet":
            import pyarrow.parquet as pq

            # parquet keeps no checksum: a damaged byte inside a text cell reads fine and fails later, when the
            # text is decoded, as a library's traceback; full validation finds it here (invalid UTF-8)
            pq.read_table(path).validate(full=True)
        df = pd.read_csv(path, dtype=str, keep_default_na=False) if path.suffix == ".csv" else pd.read_parquet(path)
    except Exception as exc:  # pyarrow and pandas raise many kinds on a damaged file
        raise FrameSetError(f"cannot read table {path}: {exc}") from exc
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise FrameSetError(f"{path} lacks columns {missing}")
    return df


def _check_objects(root: Path, objects: pd.DataFrame, descriptions: dict) -> None:
    dup = objects.object_id[objects.object_id.duplicated()]
    if len(dup):
        raise FrameSetError(f"{root / OBJECTS} lists object id {dup.iloc[0]!r} twice")
    bad_split = objects[~objects.split.isin(SPLITS)]
    if len(bad_split):
        raise FrameSetError(f"{root / OBJECTS}: object {bad_split.iloc[0].object_id!r} has split "
                            f"{bad_split.iloc[0].split!r}, expected one of {SPLITS}")
    for object_id in objects.object_id:
        folder = root / OBJECT_IMAGES / object_id
        if not folder.is_dir():
            raise FrameSetError(f"object {object_id!r}: missing reference folder {folder}")
        n = len(view_files(folder))
        if n != N_VIEWS:
            raise FrameSetError(f"object {object_id!r}: {folder} holds {n} reference views, expected {N_VIEWS}")
        texts = descriptions.get(object_id)
        if not isinstance(texts, list) or len(texts) != N_DESCRIPTIONS or not all(isinstance(t, str) and t.strip()
                                                                                   for t in texts):
            got = len(texts) if isinstance(texts, list) else "none"
            raise FrameSetError(f"object {object_id!r}: {root / DESCRIPTIONS} holds {got} descriptions, "
                                f"expected {N_DESCRIPTIONS} non-empty strings")
    extra = sorted(set(descriptions) - set(objects.object_id))
    if extra:
        raise FrameSetError(f"{root / DESCRIPTIONS} describes unknown object id {extra[0]!r}")


def _episodes_table(root: Path, records: list[dict], objects: pd.DataFrame) -> pd.DataFrame:
    known = set(objects.object_id)
    category = dict(zip(objects.object_id, objects.category))
    rows = []
    for rec in records:
        if not isinstance(rec, dict):
            raise FrameSetError(f"{root / EPISODES}: an episode must be a JSON object, got {str(rec)[:60]!r}")
        try:
            episode_id = str(rec["episode_id"])
            target_id = str(rec["goals"][0]["object_id"])
            distractors = [str(d["object_id"]) for d in rec.get("distractors", [])]
            split, scene = str(rec["split"]), str(rec.get("scene_id", ""))
        except (KeyError, IndexError, TypeError, AttributeError) as exc:
            raise FrameSetError(f"{root / EPISODES}: malformed episode {rec.get('episode_id', rec)!r}: "
                                f"missing {exc}") from exc
        for object_id in [target_id, *distractors]:
            if object_id not in known:
                raise FrameSetError(f"{root / EPISODES}: episode {episode_id!r} refers to unknown object id "
                                    f"{object_id!r}")
        rows.append(dict(episode_id=episode_id, split=split, scene_id=scene, target_object_id=target_id,
                         target_category=category[target_id], distractor_object_ids=distractors))
    df = pd.DataFrame(rows, columns=["episode_id", "split", "scene_id", "target_object_id", "target_category",
                                     "distractor_object_ids"])
    dup = df.episode_id[df.episode_id.duplicated()]
    if len(dup):
        raise FrameSetError(f"{root / EPISODES} lists episode id {dup.iloc[0]!r} twice")
    return df


def _check_types(path: Path, df: pd.DataFrame, text: list[str], integers: list[str]) -> None:
    """Wrong-typed cells are refused here, naming the column, not met later as a library's traceback."""
    for col in text:
        bad = df[~df[col].map(lambda v: isinstance(v, str))]
        if len(bad):
            raise FrameSetError(f"{path}: column {col!r} must hold text, row {bad.index[0]} holds {bad.iloc[0][col]!r}")
    for col in integers:
        if len(df) and not pd.api.types.is_integer_dtype(df[col]):
            raise FrameSetError(f"{path}: column {col!r} must hold integers, found {df[col].dtype}")


def _check_frames(root: Path, frames: pd.DataFrame, episodes: pd.DataFrame) -> None:
    _check_types(root / FRAMES, frames, ["frame_id", "episode_id", "image", "mask"], ["step"])
    unknown = frames[~frames.episode_id.isin(episodes.episode_id)]
    if len(unknown):
        raise FrameSetError(f"{root / FRAMES}: frame {unknown.iloc[0].frame_id!r} belongs to unknown episode id "
                            f"{unknown.iloc[0].episode_id!r}")
    dup = frames.frame_id[frames.frame_id.duplicated()]
    if len(dup):
        raise FrameSetError(f"{root / FRAMES} lists frame id {dup.iloc[0]!r} twice")
    columns = ["image", "mask"] + (["depth"] if "depth" in frames.columns else [])
    for col in columns:
        for frame_id, rel in zip(frames.frame_id, frames[col]):
            if col == "depth" and not isinstance(rel, str):
                continue
            if not (root / rel).is_file():
                raise FrameSetError(f"frame {frame_id!r}: missing {col} file {root / rel}")


def is_approach_distance(value: object) -> bool:
    """An approach view's distance to its object: a finite number of metres >= 0."""
    try:
        return bool(np.isfinite(float(value)) and float(value) >= 0)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False


def _check_approach_views(root: Path, frames: pd.DataFrame, episodes: pd.DataFrame) -> None:
    """An approach view names an object of its own episode and a finite distance >= 0 to it; both columns or
    neither."""
    path = root / FRAMES
    if ("approach_of" in frames.columns) != ("approach_distance" in frames.columns):
        raise FrameSetError(f"{path}: approach views need both columns 'approach_of' and 'approach_distance'")
    if "approach_of" not in frames.columns:
        return
    views = frames[frames.approach_of.notna()]
    placed = {e: {t, *d} for e, t, d in zip(episodes.episode_id, episodes.target_object_id,
                                           episodes.distractor_object_ids)}
    for frame_id, episode_id, object_id, distance in zip(views.frame_id, views.episode_id, views.approach_of,
                                                         views.approach_distance):
        if not isinstance(object_id, str) or object_id not in placed.get(episode_id, ()):
            raise FrameSetError(f"{path}: frame {frame_id!r} is an approach view of {object_id!r}, which is not an "
                                f"object of its episode {episode_id!r}")
        if not is_approach_distance(distance):
            raise FrameSetError(f"{path}: frame {frame_id!r} has approach_distance {distance!r}, not a finite "
                                "distance >= 0 m")


def _check_visibility(root: Path, vis: pd.DataFrame, frames: pd.DataFrame, objects: pd.DataFrame) -> None:
    _check_types(root / VISIBILITY, vis, ["frame_id", "role"], ["mask_value", "pixels", "x0", "y0", "x1", "y1"])
    unknown = vis[~vis.frame_id.isin(frames.frame_id)]
    if len(unknown):
        raise FrameSetError(f"{root / VISIBILITY} refers to unknown frame id {unknown.iloc[0].frame_id!r}")
    named = vis[vis.object_id.notna() & (vis.object_id != "")]
    unknown = named[~named.object_id.isin(objects.object_id)]
    if len(unknown):
        raise FrameSetError(f"{root / VISIBILITY} refers to unknown object id {unknown.iloc[0].object_id!r}")
    bad = vis[~vis.role.isin(ROLES)]
    if len(bad):
        raise FrameSetError(f"{root / VISIBILITY}: role {bad.iloc[0].role!r} is not one of {ROLES}")
