"""Turn what a PIN user records in Habitat into a frame-set.

A recording folder holds, per episode, the RGB frames, the semantic frames with PIN's
labels (100000 target, 100001 same-category distractor, 100002 other distractor) and
optionally depth, next to the PInNED episodes JSON; a PInNED objects folder holds the
references. PIN's semantic sensor gives one label per role, not per instance, so
distractor rows in the visibility table carry the role with an empty object id.

Layout (docs/frameset.md, "Recordings from PIN")::

    recording/episodes.json[.gz]        PInNED episodes (episode_id, goals[0], distractors[], optional split)
    recording/<episode_id>/rgb/<step>.png|.jpg
    recording/<episode_id>/semantic/<step>.npy     int, PIN labels
    recording/<episode_id>/depth/<step>.npy        float metres (optional)
    objects/objects_images/<object_id>/<object_id>_<k>.png   k = 0 frontal, 1 back, 2 top; every goal AND distractor
    objects/objects_descriptions.json              {object_id: [3 descriptions]}, the same objects

Frames keep their source bytes by default (lossless: a PNG stays PNG, a JPEG is not
re-compressed); ``image_format="png"`` or ``"jpeg"`` re-encode.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from pin_match import atomic
from pin_match.data.agent import CAMERA_HEIGHT, HFOV_DEG
from pin_match.data.frameset import (
    DESCRIPTIONS,
    IMAGE_SUFFIXES,
    N_VIEWS,
    OBJECT_IMAGES,
    SPLITS,
    FrameSet,
    FrameSetError,
)
from pin_match.data.geometry import CameraModel, EpisodeGeometry, GeometryError, Pose
from pin_match.data.images import read_image
from pin_match.data.writer import Frame, FrameSetWriter, ImageFile

TARGET_ID, SAME_CATEGORY_ID, OTHER_ID = 100000, 100001, 100002
# PIN label -> (mask value, role) in the frame-set's instance mask
LABELS = {TARGET_ID: (1, "target"), SAME_CATEGORY_ID: (2, "same_category"), OTHER_ID: (3, "other")}
IMAGE_FORMATS = ("source", "png", "jpeg")
POSES = "poses.json"  # per episode (``FrameRecorder``): camera hfov and height, and per step gps, compass, pitch
APPROACH = "approach.json"  # per episode, where recorded: the steps that are approach views, {step: [object, metres]}
JPEG_SUFFIXES = (".jpg", ".jpeg")


def _load_episodes(recording: Path) -> list[dict]:
    for name in ("episodes.json", "episodes.json.gz"):
        path = recording / name
        if path.exists():
            data = atomic.read_json(path, FrameSetError, "PInNED episodes file")
            episodes = data.get("episodes") if isinstance(data, dict) else data
            if not isinstance(episodes, list):
                raise FrameSetError(f"{path}: expected a list of episodes (or {{'episodes': [...]}})")
            return episodes
    raise FrameSetError(f"missing file {recording / 'episodes.json'} (PInNED episodes)")


def _descriptions(objects: Path) -> dict[str, list[str]]:
    path = objects / DESCRIPTIONS
    raw = atomic.read_json(path, FrameSetError)  # a missing one: "missing file PATH"
    if not isinstance(raw, dict):
        raise FrameSetError(f"{path}: expected {{object_id: [3 descriptions]}}")
    out = {}
    for k, v in raw.items():
        texts = v.get("descriptions") if isinstance(v, dict) else v
        if not isinstance(texts, list) or not all(isinstance(t, str) and t.strip() for t in texts):
            raise FrameSetError(f"{path}: object {k!r} needs a list of 3 non-empty descriptions, got {str(v)[:80]}")
        out[str(k)] = texts
    return out


def _frame_files(folder: Path, suffixes: tuple[str, ...]) -> dict[int, Path]:
    if not folder.is_dir():
        return {}
    out = {}
    for p in folder.iterdir():
        if p.suffix.lower() in suffixes:
            try:
                out[int(p.stem)] = p
            except ValueError:
                raise FrameSetError(f"{p}: frame files must be named by their step number") from None
    return out


def import_recording(recording: str | Path, objects: str | Path, out: str | Path, *, split: str = "val",
                     name: str | None = None, image_format: str = "source", overwrite: bool = False) -> FrameSet:
    """Build a frame-set at ``out`` from a recording folder and a PInNED objects folder.

    ``split`` is the split of episodes without a ``split`` key; every object takes the split of
    the episodes that use it. ``image_format``: "source" (keep each file's bytes), "png" or "jpeg".
    """
    recording, objects = Path(recording), Path(objects)
    if image_format not in IMAGE_FORMATS:
        raise FrameSetError(f"image format {image_format!r} is not one of {IMAGE_FORMATS}")
    episodes = _load_episodes(recording)
    descriptions = _descriptions(objects)
    categories, splits = _objects_of(episodes, split, recording)
    poses = _recorded_poses(recording, episodes)
    camera = None if poses is None else CameraModel(_same_camera(poses, recording)["hfov_deg"])
    writer = FrameSetWriter(out, name or recording.name, overwrite=overwrite,
                            provenance=dict(importer="pin_match.data.importer", recording=str(recording),
                                            image_format=image_format), camera=camera)
    with writer:
        for object_id, category in categories.items():
            if object_id not in descriptions:
                raise FrameSetError(f"object {object_id!r}: no entry in {objects / DESCRIPTIONS} (every goal and "
                                    "distractor needs 3 descriptions)")
            views = [read_image(p, rgba=True) for p in reference_files(objects / OBJECT_IMAGES / object_id, object_id)]
            writer.add_object(object_id, category, splits[object_id], views, descriptions[object_id])
        for ep in episodes:
            episode_id = str(ep["episode_id"])
            target = str(ep["goals"][0]["object_id"])
            writer.add_episode(episode_id, _split(ep, split), str(ep.get("scene_id", "")), target,
                               [str(d["object_id"]) for d in ep.get("distractors", [])])
            steps = None
            if poses is not None:
                writer.add_geometry(episode_id, episode_in_start_frame(ep, recording))
                steps = poses[episode_id]
            _import_episode(writer, recording / episode_id, (episode_id, target), image_format, steps)
        return writer.close()


def _split(ep: dict, default: str) -> str:
    value = str(ep.get("split", default))
    if value not in SPLITS:
        raise FrameSetError(f"episode {ep.get('episode_id')!r}: split {value!r} is not one of {SPLITS}")
    return value


def _objects_of(episodes: list[dict], default_split: str, recording: Path) -> tuple[dict[str, str], dict[str, str]]:
    """Category and split of every object an episode names (goal or distractor), in first-use order."""
    categories: dict[str, str] = {}
    splits: dict[str, str] = {}
    for ep in episodes:
        if not isinstance(ep, dict) or "episode_id" not in ep or not ep.get("goals"):
            raise FrameSetError(f"{recording}: every episode needs an episode_id and goals, got {str(ep)[:80]}")
        ep_split = _split(ep, default_split)
        for goal in [ep["goals"][0], *ep.get("distractors", [])]:
            if not isinstance(goal, dict) or "object_id" not in goal or "object_category" not in goal:
                raise FrameSetError(f"episode {ep['episode_id']!r}: goal or distractor without object_id and "
                                    f"object_category: {str(goal)[:80]}")
            oid = str(goal["object_id"])
            categories.setdefault(oid, str(goal["object_category"]))
            if splits.setdefault(oid, ep_split) != ep_split:
                raise FrameSetError(f"object {oid!r} is used by {splits[oid]} and {ep_split} episodes: an object "
                                    "belongs to one split")
    return categories, splits


def reference_files(folder: Path, object_id: str) -> list[Path]:
    """``<id>_0`` (frontal), ``<id>_1`` (back), ``<id>_2`` (top): the order is the names', never a sort guess."""
    if not folder.is_dir():
        raise FrameSetError(f"object {object_id!r}: missing reference folder {folder} (every goal and distractor "
                            "needs one)")
    out = []
    for k in range(N_VIEWS):
        found = [f for f in (folder / f"{object_id}_{k}{ext}" for ext in IMAGE_SUFFIXES) if f.is_file()]
        if len(found) != 1:
            present = sorted(p.name for p in folder.iterdir())
            raise FrameSetError(f"object {object_id!r}: needs exactly one {object_id}_{k}.png (view {k}: 0 frontal, "
                                f"1 back, 2 top) in {folder}, found {present}")
        out.append(found[0])
    return out


def _import_episode(writer: FrameSetWriter, folder: Path, ids: tuple[str, str], image_format: str,
                    poses: dict | None) -> None:
    """One recorded episode's frames (``ids``: its id and its target's), each with its camera pose when recorded."""
    episode_id, target = ids
    rgb = _frame_files(folder / "rgb", IMAGE_SUFFIXES)
    if not rgb:
        raise FrameSetError(f"episode {episode_id!r}: no RGB frames in {folder / 'rgb'}")
    semantic = _frame_files(folder / "semantic", (".npy",))
    depth = _frame_files(folder / "depth", (".npy",))
    legend = {1: (target, "target"), 2: (None, "same_category"), 3: (None, "other")}
    approach = _approach_steps(folder / APPROACH)
    for step in sorted(rgb):
        if step not in semantic:
            raise FrameSetError(f"episode {episode_id!r}: frame {rgb[step]} has no semantic frame "
                                f"{folder / 'semantic' / f'{step}.npy'}")
        image = read_image(rgb[step])
        labels = _load_array(semantic[step])
        if labels.shape[:2] != image.shape[:2] or labels.size != image.shape[0] * image.shape[1] \
                or not np.issubdtype(labels.dtype, np.integer):
            raise FrameSetError(f"{semantic[step]}: must be integer labels of shape {image.shape[:2]}, got "
                                f"{labels.dtype} {labels.shape}")
        mask = np.zeros(labels.shape[:2], np.uint16)
        for label, (value, _) in LABELS.items():
            mask[labels.reshape(mask.shape) == label] = value
        d = None
        if step in depth:
            d = _load_array(depth[step])
            if d.size != mask.size or not np.issubdtype(d.dtype, np.number):
                raise FrameSetError(f"{depth[step]}: must be depth in metres of shape {mask.shape}, got "
                                    f"{d.dtype} {d.shape}")
            d = d.reshape(mask.shape).astype(np.float32)
        pose = None if poses is None else _camera_pose(poses, step, folder / POSES)
        writer.write_frame(episode_id, step, Frame(image, mask, legend, d, pose, approach.get(step)),
                           _stored_image(rgb[step], image_format))


def _approach_steps(path: Path) -> dict[int, tuple[str, float]]:
    """The recorded episode's approach views (``FrameRecorder.record(..., approach=)``): step -> (object id,
    horizontal metres to it); none where the episode recorded no ``approach.json``."""
    if not path.is_file():
        return {}
    data = atomic.read_json(path, FrameSetError, "recorded approach views")
    try:
        return {int(step): (str(view[0]), float(view[1])) for step, view in data["views"].items()}
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise FrameSetError(f"{path}: expected {{'views': {{step: [object id, metres], ...}}}} ({exc})") from exc


def _stored_image(path: Path, image_format: str) -> ImageFile:
    """How one source frame is stored: re-encoded as PNG or JPEG, or (``source``) its own bytes as they are."""
    if image_format == "png":
        return ImageFile(".png")
    if image_format == "jpeg":
        return ImageFile(".jpg")
    return ImageFile(".jpg" if path.suffix.lower() in JPEG_SUFFIXES else ".png", path.read_bytes())


def _load_array(path: Path) -> np.ndarray:
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise FrameSetError(f"cannot read array {path}: {exc}") from exc


# ------------------------------------------------------------------ geometry: Habitat's frames into the house frame
def _recorded_poses(recording: Path, episodes: list[dict]) -> dict[str, dict] | None:
    """Each episode's ``poses.json`` when every episode has one, None when none has; a mix is refused.

    A file without the camera's ``hfov_deg`` or ``camera_height`` (one not written by a
    ``FrameRecorder``) gets PIN's, with a warning naming it: the geometry is only as right as the
    camera, so the guess is said out loud, once here, and read as recorded everywhere after."""
    found = {str(ep["episode_id"]): recording / str(ep["episode_id"]) / POSES for ep in episodes}
    have = [e for e, p in found.items() if p.is_file()]
    if not have:
        return None
    lacking = sorted(set(found) - set(have))
    if lacking:
        raise GeometryError(f"{recording}: episode {have[0]!r} recorded the agent's poses ({POSES}) but episode "
                            f"{lacking[0]!r} did not: record gps and compass in every episode or in none")
    pin, out, without_camera = {"hfov_deg": HFOV_DEG, "camera_height": CAMERA_HEIGHT}, {}, []
    for episode_id, path in found.items():
        data = atomic.read_json(path, GeometryError, "recorded poses")
        steps = data.get("gps_compass_pitch") if isinstance(data, dict) else None
        if not isinstance(steps, list) or not all(isinstance(s, list) and len(s) == 4 for s in steps):
            raise GeometryError(f"{path}: expected {{'gps_compass_pitch': [[forward, right, compass, pitch], ...]}}")
        if set(pin) - set(data):
            without_camera.append((path, sorted(set(pin) - set(data))))
        out[episode_id] = {**pin, **data}
    if without_camera:
        (first, missing), more = without_camera[0], len(without_camera) - 1
        warnings.warn(f"{first}{f' (and {more} more {POSES})' if more else ''} records no {' or '.join(missing)}: "
                      f"PIN's camera assumed ({HFOV_DEG:g} degrees wide, {CAMERA_HEIGHT:g} m high); a "
                      f"FrameRecorder writes both", stacklevel=3)
    return out


def _same_camera(poses: dict[str, dict], recording: Path) -> dict:
    cameras = {(float(p["hfov_deg"]), float(p["camera_height"])) for p in poses.values()}
    if len(cameras) > 1:
        raise GeometryError(f"{recording}: episodes recorded with different cameras {sorted(cameras)}: one "
                            "frame-set has one camera")
    hfov, height = cameras.pop()
    return {"hfov_deg": hfov, "camera_height": height}


def _camera_pose(poses: dict, step: int, path: Path) -> Pose:
    """PIN's gps (forward, right from the start) and compass (left positive) as a pose in the start frame
    (x forward, y left, z up: home-robot's reading of the same sensors)."""
    steps = poses["gps_compass_pitch"]
    if step >= len(steps):
        raise GeometryError(f"{path}: no pose for step {step} (it holds {len(steps)})")
    forward, right, compass, pitch = (float(v) for v in steps[step])
    return Pose(forward, -right, float(poses["camera_height"]), compass, pitch)


def episode_in_start_frame(ep: dict, recording: Path) -> EpisodeGeometry:
    """PIN's episode geometry (Habitat's world frame: y up, the agent looking along -z) in the episode's start frame,
    where the recorded gps and compass place the agent: the start at the origin facing +x, z up."""
    where = f"{recording}: episode {ep.get('episode_id')!r}"
    try:
        origin = np.asarray(ep["start_position"], np.float64)
        rotation = np.asarray(ep["start_rotation"], np.float64)
        geodesic = float(ep["info"]["geodesic_distance"])
        positions = {str(g["object_id"]): _into_start(np.asarray(g["position"], np.float64), origin, rotation)
                     for g in [ep["goals"][0], *ep.get("distractors", [])] if "position" in g}
        target = str(ep["goals"][0]["object_id"])
        if target not in positions or origin.shape != (3,) or rotation.shape != (4,):
            raise KeyError("goals[0].position")
    except (KeyError, TypeError, ValueError) as exc:
        raise GeometryError(f"{where} has recorded poses but lacks PIN's geometry field {exc} (start_position, "
                            "start_rotation, info.geodesic_distance, goals[0].position)") from exc
    return EpisodeGeometry(Pose(0.0, 0.0, 0.0, 0.0), geodesic, positions, {})


def _into_start(point: np.ndarray, origin: np.ndarray, rotation_xyzw: np.ndarray) -> tuple[float, float, float]:
    """A Habitat world point in the start frame: rotated by the inverse of the start rotation, then (x right, y up,
    z back) read as (x forward, y left, z up)."""
    v = _rotate_inverse(rotation_xyzw, point - origin)
    return float(-v[2]), float(-v[0]), float(v[1])


def _rotate_inverse(q_xyzw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` rotated by the conjugate of the unit quaternion ``q`` ([x, y, z, w], Habitat's coefficient order)."""
    norm = float(np.linalg.norm(q_xyzw))
    if not np.isfinite(norm) or norm == 0.0:
        raise ValueError(f"start_rotation {q_xyzw.tolist()} is not a rotation")
    u, w = -q_xyzw[:3] / norm, q_xyzw[3] / norm
    return v + 2.0 * w * np.cross(u, v) + 2.0 * np.cross(u, np.cross(u, v))
