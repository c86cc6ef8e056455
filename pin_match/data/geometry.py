"""Where the camera was and where the objects are: the optional geometry of a frame-set.

PIN judges a detection module by what the agent does with it (SR, SPL, CE, D2G, Steps), and
that needs the walk's geometry: per frame the camera pose in the episode's house frame, the
camera's field of view, per episode the start pose, the shortest-path (geodesic) length to the
target and each placed object's position. The house frame is metric and right-handed with z up
(x, y on the floor); a yaw of 0 looks along +x and turns counter-clockwise, a positive pitch
looks up. Habitat's frames are converted by their producer (``importer``) into this one.

Stored where PIN keeps the same facts: the field of view in the manifest (``geometry``, with
its own version), the poses as columns of ``frames.parquet`` and, in ``episodes.json``,
``start_position`` / ``start_yaw`` / ``info.geodesic_distance`` per episode and ``position`` (and,
where known, ``geodesic_distance``) per goal and distractor. A frame-set without them loads as
before; ``missing_reason`` says what a navigation estimate lacks.

Where the producer knows the floor plan (the synthetic generator), an episode also carries its
``floor_map``: the cells of the floor where an agent of PIN's radius can stand (a PNG under
``maps/``, 255 = standable, its cell size and origin in the episode's record). PIN's agent stops
on the floor, beside furniture, never on the object it found; the navigation estimate reads
where it stands from the map (``FloorMap.stand``), and a recording without one falls back to a
stated rule (``evaluation.core.navigation``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match.data.paths import GridWalks
from pin_match.errors import PinMatchError

GEOMETRY_VERSION = 1  # the floor map is optional: a reader of version 1 that ignores it reads the rest unchanged
AGENT_RADIUS = 0.17  # metres: PIN's agent (its configuration), the body a standable cell must hold
MAPS = "maps"  # folder of the episodes' floor maps
POSE_COLUMNS = ("pose_x", "pose_y", "pose_z", "pose_yaw", "pose_pitch")  # metres, metres, metres, radians, radians


class GeometryError(PinMatchError, ValueError):
    """Geometry that cannot be true (a NaN pose, a negative distance) or that a producer left half written."""


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera with square pixels and its principal point at the frame's centre (Habitat's and the
    synthetic renderer's), known by its horizontal field of view."""

    hfov_deg: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.hfov_deg) and 0.0 < self.hfov_deg < 180.0):
            raise GeometryError(f"horizontal field of view {self.hfov_deg!r} degrees is not in (0, 180)")

    def focal_px(self, width: int) -> float:
        return width / 2.0 / math.tan(math.radians(self.hfov_deg) / 2.0)

    def manifest(self) -> dict:
        return {"version": GEOMETRY_VERSION, "hfov_deg": self.hfov_deg}


@dataclass(frozen=True)
class Pose:
    """A camera pose in the house frame: position (metres), yaw and pitch (radians)."""

    x: float
    y: float
    z: float
    yaw: float
    pitch: float = 0.0

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.x, self.y, self.z, self.yaw, self.pitch)):
            raise GeometryError(f"camera pose {self} is not finite")

    def row(self) -> dict[str, float]:
        return dict(zip(POSE_COLUMNS, (self.x, self.y, self.z, self.yaw, self.pitch)))

    @property
    def position(self) -> np.ndarray:
        return np.array([self.x, self.y, self.z])


@dataclass(frozen=True, eq=False)
class FloorMap:
    """Where an agent of radius ``agent_radius`` can stand: a grid over the floor, ``free[i, j]`` for the cell whose
    centre is ``origin + (i + 0.5, j + 0.5) * cell`` (i along x, j along y)."""

    free: np.ndarray
    cell: float
    origin: tuple[float, float] = (0.0, 0.0)
    agent_radius: float = AGENT_RADIUS

    def __post_init__(self) -> None:
        if self.free.ndim != 2 or self.free.dtype != bool:
            raise GeometryError(f"a floor map is a 2-d boolean grid, got {self.free.dtype} of shape {self.free.shape}")
        if not (math.isfinite(self.cell) and self.cell > 0):
            raise GeometryError(f"floor map cell size {self.cell!r} is not a positive length")
        if not self.free.any():
            raise GeometryError("a floor map with no standable cell: the agent could stand nowhere")

    @property
    def centres(self) -> np.ndarray:
        """(K, 2) centres of the standable cells."""
        return (np.argwhere(self.free) + 0.5) * self.cell + np.asarray(self.origin)

    def stand(self, goal_xy: np.ndarray, eye_xy: np.ndarray) -> np.ndarray:
        """Where an agent at ``eye_xy`` that walks to ``goal_xy`` stops: the standable cell nearest the goal among
        those it can walk to (the part of the floor holding the standable cell nearest it), the nearer to it
        first among equals."""
        centres, parts = self.centres, self.walks.parts()
        from_eye = np.hypot(*(centres - np.asarray(eye_xy)[:2]).T)
        reach = parts == parts[int(np.argmin(from_eye))]
        to_goal = np.hypot(*(centres[reach] - np.asarray(goal_xy)[:2]).T)
        best = np.flatnonzero(to_goal <= to_goal.min() + 1e-9)
        return centres[reach][best[int(np.argmin(from_eye[reach][best]))]]

    def walk_length(self, a_xy: Sequence[float], b_xy: Sequence[float]) -> float:
        """The shortest walk on the map from ``a_xy`` to ``b_xy`` (x, y): from the standable cell nearest each point,
        8-connected cells (a diagonal step sqrt(2) cells), plus the straight bits from the points to their cells;
        the straight line where no walk joins them (two parts of the floor). What PIN's agent walks after a commit,
        around walls and furniture, never through them."""
        centres = self.centres
        a, b = self._nearest_cell(a_xy), self._nearest_cell(b_xy)
        walked = self.walks.from_node(a)[0][b]
        ends = float(np.hypot(*(centres[a] - np.asarray(a_xy)[:2])) + np.hypot(*(centres[b] - np.asarray(b_xy)[:2])))
        return float(walked + ends) if np.isfinite(walked) else float(np.hypot(*(np.asarray(b_xy)[:2] -
                                                                                   np.asarray(a_xy)[:2])))

    def geodesic(self, start_xy: Sequence[float], goal_xy: Sequence[float]) -> float:
        """PIN's ``geodesic_distance`` as a synthetic set measures it: the shortest walk on this map from the start to
        where an agent walking to the goal stands (``stand``), on the graph and with the stopping rule of the agent's
        own walk to a goal (``walk_length``), so SPL's two sides are measured alike."""
        return self.walk_length(start_xy, self.stand(np.asarray(goal_xy, np.float64)[:2], np.asarray(start_xy)[:2]))

    def path(self, a_xy: Sequence[float], b_xy: Sequence[float]) -> np.ndarray:
        """The shortest walk of ``walk_length`` as waypoints (K, 2), from ``a_xy`` through the standable cells'
        centres to ``b_xy``; the straight line where no walk joins them."""
        cells = self.walks.path(self._nearest_cell(a_xy), self._nearest_cell(b_xy))
        ends = np.asarray(a_xy, np.float64)[:2], np.asarray(b_xy, np.float64)[:2]
        return np.vstack([ends[0], self.centres[cells], ends[1]]) if cells else np.stack(ends)

    def _nearest_cell(self, xy: Sequence[float]) -> int:
        """The standable cell nearest a point (an index into ``centres``)."""
        return int(np.argmin(np.hypot(*(self.centres - np.asarray(xy, np.float64)[:2]).T)))

    @property
    def walks(self) -> GridWalks:
        """The map's shortest walks (``paths.GridWalks``), built on first use and kept."""
        if "_walks" not in self.__dict__:
            self.__dict__["_walks"] = GridWalks(self.free, self.cell)
        return self.__dict__["_walks"]

    def nearest(self, xyz: Sequence[float], floor: float) -> float:
        """The least distance from an agent standing anywhere on the map (on the floor at height ``floor``) to the
        point ``xyz``: how close PIN's success rule could ever count it."""
        flat = np.hypot(*(self.centres - np.asarray(xyz[:2], np.float64)).T).min()
        return float(np.hypot(flat, float(xyz[2]) - floor))

    def record(self, file: str) -> dict:
        return {"file": file, "cell": self.cell, "origin": [float(v) for v in self.origin],
                "agent_radius": self.agent_radius}

    def image(self) -> np.ndarray:
        """The map as stored: rows along y, columns along x, 255 where the agent can stand."""
        return np.ascontiguousarray(self.free.T).astype(np.uint8) * 255


def read_floor_map(root: Path, record: dict, where: str) -> FloorMap:
    """An episode's ``floor_map`` record and the PNG it names; a missing file or field names the episode."""
    from pin_match.data.images import read_label_png

    try:
        grid = read_label_png(root / str(record["file"]))
        return FloorMap(grid.T > 127, float(record["cell"]), tuple(float(v) for v in record["origin"]),
                        float(record.get("agent_radius", AGENT_RADIUS)))
    except (KeyError, TypeError, ValueError) as exc:
        raise GeometryError(f"{where}: floor_map {record!r} is unreadable: {exc}") from exc


@dataclass(frozen=True)
class EpisodeGeometry:
    """One episode's start, its geodesic length to the target, and where each placed object is.

    ``positions``: object id -> centre (x, y, z) in the house frame; ``geodesic_to``: object id ->
    shortest-path length from the start, where known (the target's is ``geodesic_distance``). The start
    is the agent's base: its height is the floor's.
    """

    start: Pose
    geodesic_distance: float
    positions: dict[str, tuple[float, float, float]]
    geodesic_to: dict[str, float]
    floor_map: FloorMap | None = None  # where the agent can stand, where the producer knows the floor plan

    def __post_init__(self) -> None:
        for name, value in (("geodesic_distance", self.geodesic_distance), *self.geodesic_to.items()):
            if not (math.isfinite(value) and value >= 0.0):
                raise GeometryError(f"geodesic distance {name!r} = {value!r} is not a finite length >= 0")
        for object_id, xyz in self.positions.items():
            if len(xyz) != 3 or not all(math.isfinite(float(v)) for v in xyz):
                raise GeometryError(f"position of object {object_id!r} = {xyz!r} is not three finite numbers")

    def annotate(self, record: dict, map_file: str | None = None) -> dict:
        """An ``episodes.json`` record with this geometry written in (PIN's field names; the floor map's record
        where it is stored in ``map_file``)."""
        out = dict(record, start_position=[self.start.x, self.start.y, self.start.z], start_yaw=self.start.yaw,
                   info={**record.get("info", {}), "geodesic_distance": self.geodesic_distance})
        if self.floor_map is not None and map_file is not None:
            out["floor_map"] = self.floor_map.record(map_file)
        for key in ("goals", "distractors"):
            out[key] = [self._object(goal) for goal in record.get(key, [])]
        return out

    def _object(self, goal: dict) -> dict:
        object_id = goal["object_id"]
        out = dict(goal)
        if object_id in self.positions:
            out["position"] = [float(v) for v in self.positions[object_id]]
        if object_id in self.geodesic_to:
            out["geodesic_distance"] = self.geodesic_to[object_id]
        return out


def episode_geometry(record: dict, where: str, root: Path | None = None) -> EpisodeGeometry:
    """The geometry of one ``episodes.json`` record (its floor map read under ``root``); a missing or impossible
    field names the episode."""
    episode = f"{where}: episode {record.get('episode_id')!r}"
    try:
        sx, sy, sz = (float(v) for v in record["start_position"])
        start = Pose(sx, sy, sz, float(record["start_yaw"]))
        geodesic = float(record["info"]["geodesic_distance"])
        positions, geodesic_to = {}, {}
        for goal in [*record["goals"][:1], *record.get("distractors", [])]:
            if "position" in goal:
                positions[str(goal["object_id"])] = tuple(float(v) for v in goal["position"])
            if "geodesic_distance" in goal:
                geodesic_to[str(goal["object_id"])] = float(goal["geodesic_distance"])
        target = str(record["goals"][0]["object_id"])
        if target not in positions:
            raise KeyError(f"goals[0].position ({target})")
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        if isinstance(exc, GeometryError):
            raise GeometryError(f"{episode}: {exc}") from exc
        raise GeometryError(f"{episode} lacks geometry field {exc} or holds a malformed one (see docs/frameset.md, "
                            "'Geometry')") from exc
    floor_map = None if root is None or "floor_map" not in record else \
        read_floor_map(root, record["floor_map"], episode)
    try:
        return EpisodeGeometry(start, geodesic, positions, geodesic_to, floor_map)
    except GeometryError as exc:
        raise GeometryError(f"{episode}: {exc}") from exc


@dataclass(frozen=True)
class Geometry:
    """A frame-set's geometry: the camera, every frame's pose (indexed by frame id) and every episode's layout."""

    camera: CameraModel
    poses: pd.DataFrame
    episodes: dict[str, EpisodeGeometry]

    def pose(self, frame_id: str) -> Pose:
        return Pose(*(float(v) for v in self.poses.loc[frame_id, list(POSE_COLUMNS)]))

    def back_project(self, frame_id: str, xy: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Frame coordinates (K, 2: x right, y down, continuous pixels) with their depth along the view axis
        (K,) -> points (K, 3) in the house frame."""
        row = self.poses.loc[frame_id]
        return back_project(self.pose(frame_id), self.camera.focal_px(int(row["width"])),
                            (float(row["width"]) / 2.0, float(row["height"]) / 2.0), xy, depth)


def camera_axes(pose: Pose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward, right and up unit vectors of a camera in the house frame."""
    cy, sy, cp, sp = math.cos(pose.yaw), math.sin(pose.yaw), math.cos(pose.pitch), math.sin(pose.pitch)
    forward = np.array([cy * cp, sy * cp, sp])
    right = np.array([sy, -cy, 0.0])
    return forward, right, np.cross(right, forward)


def back_project(pose: Pose, focal: float, centre: tuple[float, float], xy: np.ndarray,
                 depth: np.ndarray) -> np.ndarray:
    """Pinhole back-projection: each pixel's ray scaled so that its distance along the view axis is ``depth``."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    d = np.asarray(depth, np.float64).reshape(-1, 1)
    forward, right, up = camera_axes(pose)
    along_right = (xy[:, :1] - centre[0]) / focal
    along_up = (centre[1] - xy[:, 1:]) / focal
    return pose.position + d * (forward + along_right * right + along_up * up)


def read_geometry(root: Path, manifest: dict, frames: pd.DataFrame, records: list[dict]) -> Geometry | None:
    """A frame-set's geometry when its manifest declares one (validated whole), else None."""
    declared = manifest.get("geometry")
    if declared is None:
        return None
    where = root / "frameset.json"
    if not isinstance(declared, dict) or not isinstance(declared.get("version"), int):
        raise GeometryError(f"{where}: 'geometry' must be {{'version': int, 'hfov_deg': number}}")
    if declared["version"] > GEOMETRY_VERSION:
        raise GeometryError(f"{where}: geometry version {declared['version']} is newer than this pin_match reads "
                            f"({GEOMETRY_VERSION}): upgrade pin_match")
    try:
        camera = CameraModel(float(declared["hfov_deg"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise GeometryError(f"{where}: geometry lacks a numeric 'hfov_deg' ({exc})") from exc
    poses = _poses(root / "frames.parquet", frames)
    episodes = {str(r["episode_id"]): episode_geometry(r, str(root / "episodes.json"), root) for r in records}
    return Geometry(camera, poses, episodes)


def _poses(path: Path, frames: pd.DataFrame) -> pd.DataFrame:
    missing = [c for c in POSE_COLUMNS if c not in frames.columns]
    if missing:
        raise GeometryError(f"{path}: the manifest declares geometry but the frames lack columns {missing}")
    values = frames[list(POSE_COLUMNS)].to_numpy(np.float64)
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise GeometryError(f"{path}: frame {frames.frame_id.iloc[k]!r} has a non-finite camera pose "
                            f"{dict(zip(POSE_COLUMNS, values[k].tolist()))}")
    return frames.set_index("frame_id")[[*POSE_COLUMNS, "height", "width"]]


def missing_reason(manifest: dict, frames: pd.DataFrame) -> str | None:
    """Why a navigation estimate cannot be made on a frame-set (None when it can)."""
    if manifest.get("geometry") is None:
        return ("the frame-set records no geometry (camera poses, object positions, geodesic lengths): rebuild it "
                "with a producer that writes them (pin-match synth, the PIN recorder with gps and compass)")
    if "depth" not in frames.columns or frames["depth"].isna().any():
        return "the frame-set has no depth for every frame: a matched point cannot be placed in the house"
    return None
