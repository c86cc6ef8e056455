"""Build frame-sets on disk: used by the synthetic generator and the recording importer.

The whole frame-set is written into a staging folder beside the destination and renamed
into place by ``close()``, so an interrupted build never leaves something that loads.
Frame files can be encoded in worker processes with ``encode_frame`` and their rows
handed to the writer afterwards.
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.data.frameset import (
    DESCRIPTIONS,
    EPISODES,
    FORMAT_NAME,
    FORMAT_VERSION,
    FRAMES,
    MANIFEST,
    N_DESCRIPTIONS,
    N_VIEWS,
    OBJECT_IMAGES,
    OBJECTS,
    ROLES,
    SPLITS,
    VISIBILITY,
    FrameSet,
    FrameSetError,
    is_approach_distance,
)
from pin_match.data.geometry import MAPS, POSE_COLUMNS, CameraModel, EpisodeGeometry, GeometryError, Pose

VISIBILITY_COLUMNS = ["frame_id", "object_id", "role", "mask_value", "pixels", "x0", "y0", "x1", "y1", "depth"]


@dataclass(frozen=True)
class Frame:
    """One camera frame as a source hands it over: the image, its instance mask, what each mask value is, depth.

    ``mask`` holds per-pixel values (0 = background); ``legend`` maps each value to
    (object id or None when the recording cannot tell instances apart, role). Depth is in metres
    along the view axis (0 or NaN: no hit); ``pose`` is the camera's in the episode's house frame.
    ``approach``: (object id, horizontal metres from the camera to its centre) for a view an agent meets
    walking up to that object to check it, which only an approach-verify policy reads (docs/frameset.md);
    None for a frame of the walk.
    """

    image: np.ndarray
    mask: np.ndarray
    legend: Mapping[int, tuple[str | None, str]]
    depth: np.ndarray | None = None
    pose: Pose | None = None
    approach: tuple[str, float] | None = None


@dataclass(frozen=True)
class ImageFile:
    """How a frame's image is stored: its file type, and the bytes of that file when a source already has them.

    ``data``, when given, is the already encoded file of the image (an importer keeping a
    recording's own bytes) and is stored as is; otherwise the image is encoded (JPEG at
    quality 95, or lossless PNG).
    """

    ext: str = ".jpg"
    data: bytes | None = None


@dataclass
class FrameRecord:
    """The table rows describing one written frame."""

    frame: dict
    visibility: list[dict]


def millimetres(depth: np.ndarray) -> np.ndarray:
    """Depth in metres as a frame-set stores it: whole millimetres, uint16 (0 where nothing was hit, at most 65.5 m)."""
    return np.clip(np.round(np.nan_to_num(depth) * 1000.0), 0, 65535).astype(np.uint16)


def check_id(kind: str, value: str) -> None:
    """Refuse an id that is not one plain folder name: object and episode ids name folders of the frame-set, so a
    '/' would nest folders the loader never finds and '..' would write outside it."""
    if not isinstance(value, str) or value in ("", ".", "..") or "/" in value or "\\" in value:
        raise FrameSetError(f"{kind} id {value!r} is not a plain name (no '/', '\\', '.' or '..'): it names a "
                            f"folder of the frame-set")


def frame_id_for(episode_id: str, step: int) -> str:
    return f"{episode_id}_{step:04d}"


def encode_frame(root: str | Path, episode_id: str, step: int, frame: Frame,
                 file: ImageFile = ImageFile()) -> FrameRecord:
    """Write one frame's image (as ``file`` says), instance mask and depth under ``root``; derive its visibility rows.

    Depth is stored in millimetres; mean depths are computed from the stored values so the
    table agrees with the file exactly.
    """
    root = Path(root)
    frame_id = frame_id_for(episode_id, step)
    image, mask, depth = frame.image, frame.mask, frame.depth
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise FrameSetError(f"frame {frame_id}: image must be H x W x 3 uint8, got {image.shape} {image.dtype}")
    if mask.shape != image.shape[:2]:
        raise FrameSetError(f"frame {frame_id}: mask shape {mask.shape} differs from image {image.shape[:2]}")
    if mask.max(initial=0) > 65535 or mask.min(initial=0) < 0:
        raise FrameSetError(f"frame {frame_id}: mask values must fit in uint16")
    rel_image = f"frames/{episode_id}/{step:04d}{file.ext}"
    rel_mask = f"masks/{episode_id}/{step:04d}.png"
    params = [1, 95] if file.ext in (".jpg", ".jpeg") else []  # cv2.IMWRITE_JPEG_QUALITY = 1
    if file.data is None:
        atomic.write_image(root / rel_image, image, params)
    else:
        atomic.write_bytes(root / rel_image, file.data)
    mask16 = mask.astype(np.uint16)
    atomic.write_image(root / rel_mask, mask16)
    row = dict(frame_id=frame_id, episode_id=episode_id, step=int(step), image=rel_image, mask=rel_mask,
               height=int(image.shape[0]), width=int(image.shape[1]),
               sha256=hashlib.sha256((root / rel_image).read_bytes()).hexdigest())
    if frame.pose is not None:
        row.update(frame.pose.row())
    if frame.approach is not None:
        row.update(_approach_columns(frame_id, frame.approach))
    depth_mm = None
    if depth is not None:
        if depth.shape != mask.shape:
            raise FrameSetError(f"frame {frame_id}: depth shape {depth.shape} differs from mask {mask.shape}")
        if (np.nan_to_num(depth) < 0).any():
            raise GeometryError(f"frame {frame_id}: depth holds negative values (min {np.nanmin(depth):g} m); "
                                "depth is metres along the view axis, 0 where nothing was hit")
        depth_mm = millimetres(depth)
        row["depth"] = f"depth/{episode_id}/{step:04d}.png"
        atomic.write_image(root / row["depth"], depth_mm)
    return FrameRecord(row, visibility_rows(frame_id, mask16, frame.legend, depth_mm))


def _approach_columns(frame_id: str, approach: tuple[str, float]) -> dict:
    object_id, distance = approach
    if not (isinstance(object_id, str) and object_id and is_approach_distance(distance)):
        raise FrameSetError(f"frame {frame_id}: approach {approach!r} is not (object id, finite distance >= 0 m)")
    return dict(approach_of=object_id, approach_distance=float(distance))


def visibility_rows(frame_id: str, mask: np.ndarray, legend: Mapping[int, tuple[str | None, str]],
                    depth_mm: np.ndarray | None = None) -> list[dict]:
    """One row per mask value present in the frame, computed from the mask itself."""
    rows = []
    values, counts = np.unique(mask, return_counts=True)
    for value, count in zip(values.tolist(), counts.tolist()):
        if value == 0:
            continue
        if value not in legend:
            raise FrameSetError(f"frame {frame_id}: mask value {value} has no entry in the legend")
        object_id, role = legend[value]
        if role not in ROLES:
            raise FrameSetError(f"frame {frame_id}: role {role!r} is not one of {ROLES}")
        ys, xs = np.nonzero(mask == value)
        mean_depth = np.nan
        if depth_mm is not None:
            d = depth_mm[ys, xs]
            d = d[d > 0]
            mean_depth = float(d.mean()) / 1000.0 if d.size else np.nan
        rows.append(dict(frame_id=frame_id, object_id=object_id or "", role=role, mask_value=int(value),
                         pixels=int(count), x0=int(xs.min()), y0=int(ys.min()), x1=int(xs.max()) + 1,
                         y1=int(ys.max()) + 1, depth=mean_depth))
    return rows


OBJECT_COLUMNS = ("object_id", "category", "split", "source", "licence")


@dataclass(frozen=True)
class ObjectOrigin:
    """Where an instance comes from (a scan, a photo) and under which licence: the objects table's last columns."""

    source: str = ""
    licence: str = ""


class FrameSetWriter:
    """Collects objects, episodes and frames, then publishes the frame-set atomically."""

    def __init__(self, root: str | Path, name: str | None = None, *, overwrite: bool = False,
                 provenance: dict | None = None, image_ext: str = ".jpg", camera: CameraModel | None = None) -> None:
        """``camera``: the frames' camera when the producer knows the geometry; then every frame needs a pose and
        every episode its ``EpisodeGeometry`` (``data.geometry``)."""
        self.root = Path(root)
        if self.root.exists() and not overwrite:
            raise FrameSetError(f"{self.root} already exists: pass --overwrite (overwrite=True) to replace it")
        try:
            self.root.parent.mkdir(parents=True, exist_ok=True)
            self.staging = Path(tempfile.mkdtemp(prefix=f".{self.root.name}.", suffix=".staging",
                                                 dir=self.root.parent))
        except OSError as exc:
            raise atomic.OutputError(f"cannot write into {self.root.parent}: {exc.strerror or exc}") from exc
        self.name = name or self.root.name
        self.provenance = provenance or {}
        self.image_ext = image_ext
        self.camera = camera
        self._geometry: set[str] = set()
        self._objects: dict[str, dict] = {}
        self._descriptions: dict[str, list[str]] = {}
        self._episodes: dict[str, dict] = {}
        self._frames: list[dict] = []
        self._visibility: list[dict] = []

    def add_object(self, object_id: str, category: str, split: str, views: Sequence[np.ndarray],
                   descriptions: Sequence[str], *, origin: ObjectOrigin | None = None) -> None:
        """Add an instance with its 3 RGBA reference views and 3 descriptions; ``origin`` fills the objects
        table's ``source`` and ``licence`` columns (where the instance comes from, under which licence)."""
        check_id("object", object_id)
        if object_id in self._objects:
            raise FrameSetError(f"object id {object_id!r} added twice")
        if split not in SPLITS:
            raise FrameSetError(f"object {object_id!r}: split {split!r} not in {SPLITS}")
        if len(views) != N_VIEWS or len(descriptions) != N_DESCRIPTIONS:
            raise FrameSetError(f"object {object_id!r}: needs {N_VIEWS} views and {N_DESCRIPTIONS} descriptions, "
                                f"got {len(views)} and {len(descriptions)}")
        for k, view in enumerate(views):
            if view.ndim != 3 or view.shape[2] != 4:
                raise FrameSetError(f"object {object_id!r}: view {k} must be RGBA")
            atomic.write_image(self.staging / OBJECT_IMAGES / object_id / f"{object_id}_{k}.png", view)
        origin = origin or ObjectOrigin()
        self._objects[object_id] = dict(object_id=object_id, category=category, split=split, source=origin.source,
                                        licence=origin.licence)
        self._descriptions[object_id] = list(descriptions)

    def add_episode(self, episode_id: str, split: str, scene_id: str, target_object_id: str,
                    distractor_object_ids: Sequence[str], geometry: EpisodeGeometry | None = None) -> None:
        check_id("episode", episode_id)
        if episode_id in self._episodes:
            raise FrameSetError(f"episode id {episode_id!r} added twice")
        for object_id in [target_object_id, *distractor_object_ids]:
            if object_id not in self._objects:
                raise FrameSetError(f"episode {episode_id!r}: unknown object id {object_id!r}")

        def goal(oid: str) -> dict:
            return dict(object_id=oid, object_category=self._objects[oid]["category"])

        self._episodes[episode_id] = dict(episode_id=episode_id, split=split, scene_id=scene_id,
                                          goals=[goal(target_object_id)],
                                          distractors=[goal(o) for o in distractor_object_ids])
        if geometry is not None:
            self.add_geometry(episode_id, geometry)

    def add_geometry(self, episode_id: str, geometry: EpisodeGeometry) -> None:
        """An episode's start, geodesic lengths, object positions and floor map (a renderer knows them once it has
        placed the objects); a writer with a camera needs them for every episode by ``close``."""
        if self.camera is None:
            raise GeometryError(f"episode {episode_id!r}: geometry given to a writer without a camera (pass camera=)")
        if episode_id not in self._episodes:
            raise FrameSetError(f"geometry of unknown episode id {episode_id!r}")
        map_file = None
        if geometry.floor_map is not None:
            map_file = f"{MAPS}/{episode_id}.png"
            atomic.write_image(self.staging / map_file, geometry.floor_map.image())
        self._episodes[episode_id] = geometry.annotate(self._episodes[episode_id], map_file)
        self._geometry.add(episode_id)

    def roles(self, episode_id: str) -> dict[str, str]:
        """Object id -> role for every object placed in an episode."""
        ep = self._episodes[episode_id]
        target = ep["goals"][0]
        out = {target["object_id"]: "target"}
        for d in ep["distractors"]:
            out[d["object_id"]] = "same_category" if d["object_category"] == target["object_category"] else "other"
        return out

    def add_frame(self, episode_id: str, step: int, image: np.ndarray, mask: np.ndarray,
                  legend: Mapping[int, tuple[str | None, str]], depth: np.ndarray | None = None, *,
                  file: ImageFile | None = None) -> str:
        """Write one frame of a known episode (see ``Frame``); its image encoded as the writer's ``image_ext``
        unless ``file`` says otherwise. Returns its frame id."""
        return self.write_frame(episode_id, step, Frame(image, mask, legend, depth), file)

    def write_frame(self, episode_id: str, step: int, frame: Frame, file: ImageFile | None = None) -> str:
        """``add_frame`` for a whole ``Frame`` (with its camera pose, when the producer knows it)."""
        if episode_id not in self._episodes:
            raise FrameSetError(f"frame of unknown episode id {episode_id!r}")
        rec = encode_frame(self.staging, episode_id, step, frame, file or ImageFile(self.image_ext))
        self.add_frame_record(rec)
        return rec.frame["frame_id"]

    def add_frame_record(self, rec: FrameRecord) -> None:
        self._frames.append(rec.frame)
        self._visibility.extend(rec.visibility)

    def close(self) -> FrameSet:
        """Write the tables and manifest, move the frame-set into place and load it back."""
        s = self.staging
        objects = pd.DataFrame(list(self._objects.values()), columns=OBJECT_COLUMNS)
        if not (objects.source.astype(bool) | objects.licence.astype(bool)).any():
            objects = objects[list(OBJECT_COLUMNS[:3])]
        atomic.write_text(s / OBJECTS, objects.to_csv(index=False))
        atomic.write_json(s / DESCRIPTIONS, self._descriptions)
        atomic.write_json(s / EPISODES, {"episodes": list(self._episodes.values())})
        frames = pd.DataFrame(self._frames).sort_values(["episode_id", "step"], kind="stable")
        self._check_poses(frames)
        atomic.write_parquet(s / FRAMES, frames.reset_index(drop=True))
        vis = pd.DataFrame(self._visibility, columns=VISIBILITY_COLUMNS)
        vis = vis.sort_values(["frame_id", "mask_value"], kind="stable").reset_index(drop=True)
        if vis["depth"].isna().all():
            vis = vis.drop(columns="depth")
        atomic.write_parquet(s / VISIBILITY, vis)
        manifest = dict(format=FORMAT_NAME, version=FORMAT_VERSION, name=self.name, depth="depth" in frames.columns,
                        provenance=self.provenance)
        if self.camera is not None:
            manifest["geometry"] = self.camera.manifest()
        atomic.write_json(s / MANIFEST, manifest)
        if self.root.exists():
            shutil.rmtree(self.root)
        s.rename(self.root)
        return FrameSet.load(self.root)

    def _check_poses(self, frames: pd.DataFrame) -> None:
        """Poses on every frame and geometry in every episode when the writer has a camera, no pose without one:
        a half-placed walk is refused."""
        if self.camera is not None:
            lacking = sorted(set(self._episodes) - self._geometry)
            if lacking:
                raise GeometryError(f"episode {lacking[0]!r} has no geometry, but the writer has a camera")
        posed = frames[POSE_COLUMNS[0]].notna() if POSE_COLUMNS[0] in frames.columns else pd.Series(False, frames.index)
        wrong = frames[~posed] if self.camera is not None else frames[posed]
        if len(wrong):
            said = "has no camera pose, but the writer has a camera" if self.camera is not None else \
                "has a camera pose, but the writer has no camera (pass camera=)"
            raise GeometryError(f"frame {wrong.frame_id.iloc[0]!r} {said}")

    def abort(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)

    def __enter__(self) -> FrameSetWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()
