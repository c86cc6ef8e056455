"""``FrameRecorder``: PIN's evaluation loop writes what ``pin-match import`` reads, one whole episode at a time.

Each episode is written into a hidden staging folder and renamed to ``<episode_id>/`` when it
is finished; only then is it added to ``episodes.json``, the list the importer reads. A run
killed mid-episode therefore leaves whole episodes only (a staging folder, or a renamed folder
not yet listed, is invisible to the importer and cleared when that episode is recorded again),
and a rerun skips the episodes already listed. The list is rewritten under a file lock, so
PIN's parallel evaluation jobs (``--num_jobs``) can share one recording folder.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import shutil
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pin_match import atomic
from pin_match.data.agent import CAMERA_HEIGHT, HFOV_DEG
from pin_match.data.importer import APPROACH, LABELS, POSES, TARGET_ID
from pin_match.errors import PinMatchError
from pin_match.pin_agent.episode import episode_record, labels_in_episode

INDEX = "episodes.json"
LOCK = ".episodes.lock"
# home-robot's markers for pixels outside the depth sensor's range, which PIN's preprocessor
# tests for (CowObsPreprocessor._preprocess_frame); the frame-set stores them as 0 = no depth
DEPTH_REPLACEMENT_VALUES = (10000.0, 10001.0)


class RecordingError(PinMatchError, ValueError):
    """A step or an episode that cannot be recorded as PIN produced it."""


class FrameRecorder:
    """Records PIN episodes under ``root`` in the layout of docs/frameset.md ("Recordings from PIN").

    Per episode: ``start_episode(env.habitat_env.current_episode)``, ``record(observations)`` after
    every step, ``finish_episode()``; or ``with recorder.episode(ep): ...``. ``split`` ("train" or
    "val") is written into each episode; without it ``pin-match import --split`` decides. ``hfov_deg`` and
    ``camera_height`` are the RGB camera's (PIN's: 42 degrees, 1.31 m), written beside each episode's poses.
    """

    def __init__(self, root: str | Path, *, split: str | None = None, hfov_deg: float = HFOV_DEG,
                 camera_height: float = CAMERA_HEIGHT) -> None:
        self.root = atomic.ensure_dir(root)
        self.split = split
        self.camera = {"hfov_deg": float(hfov_deg), "camera_height": float(camera_height)}
        self._record: dict[str, Any] | None = None
        self._labels: set[int] = set()
        self._staging: Path | None = None
        self._steps = 0
        self._size: tuple[int, int] | None = None
        self._poses: list[list[float]] = []
        self._approach: dict[str, list] = {}
        self._this_run: set[str] = set()

    # ------------------------------------------------------------------ episodes
    def finished_episodes(self) -> dict[str, dict]:
        """Episode id -> record of every episode already listed in ``episodes.json``."""
        path = self.root / INDEX
        if not path.exists():
            return {}
        data = atomic.read_json(path, RecordingError, "the recording's episode list")
        episodes = data.get("episodes") if isinstance(data, dict) else None
        if not isinstance(episodes, list):
            raise RecordingError(f"the recording's episode list {path} holds no 'episodes' list")
        return {str(e["episode_id"]): e for e in episodes}

    @property
    def recording(self) -> bool:
        """True between ``start_episode`` and ``finish_episode`` of an episode not recorded before."""
        return self._staging is not None

    def start_episode(self, episode: Any) -> bool:
        """Open an episode; False when an earlier run finished it (its steps are then not recorded again)."""
        if self._record is not None:
            raise RecordingError(f"episode {self._record['episode_id']!r} is still open: finish_episode() first")
        record = episode_record(episode, self.split)
        episode_id = record["episode_id"]
        if episode_id in self._this_run:
            raise RecordingError(f"episode {episode_id!r} recorded twice in this run ({self.root})")
        done = self.finished_episodes().get(episode_id)
        if done is not None and (done.get("scene_id", ""), done["goals"][0]) != (record["scene_id"],
                                                                                 record["goals"][0]):
            raise RecordingError(f"episode id {episode_id!r} is already recorded in {self.root} for scene "
                                 f"{done.get('scene_id')!r}, target {done['goals'][0]['object_id']!r}: the importer "
                                 "names episode folders by id, so a recording holds each id once")
        self._this_run.add(episode_id)
        self._record, self._labels, self._steps, self._size = record, labels_in_episode(record), 0, None
        self._poses, self._approach = [], {}
        if done is None:
            self._clear_leftovers(episode_id)
            try:
                self._staging = Path(tempfile.mkdtemp(prefix=f".{episode_id}.", suffix=".staging", dir=self.root))
            except OSError as exc:
                raise atomic.OutputError(f"cannot write into {self.root}: {exc.strerror or exc}") from exc
        return done is None

    def record(self, observations: Mapping[str, Any], *, camera_pitch: float | None = None,
               approach: tuple[str, float] | None = None) -> None:
        """Store one step: ``rgb`` (H x W x 3 uint8), ``semantic`` (PIN labels), optional ``depth`` (metres), and
        where the agent stood: PIN's ``gps`` ([forward, right] metres from the start) and ``compass`` (radians, turned
        left positive), with ``camera_pitch`` (radians up, the agent's tilt, 0 = level); every step of an episode
        or none. The pitch is required with the pose: the observation does not hold it, PIN's look-up and
        look-down actions change it, and a level camera assumed for a tilted one misplaces every pixel.

        ``approach``: (object id, horizontal metres to its centre) for a step the agent took walking up to an object
        of the episode to check it, away from its walk: an approach view (docs/frameset.md), recorded after the
        walk's steps where the simulator can send the agent there and back."""
        if self._record is None:
            raise RecordingError("record() before start_episode(): open the episode first")
        if self._staging is None:
            return  # finished in an earlier run
        where = f"episode {self._record['episode_id']!r}, step {self._steps}"
        rgb, semantic, depth = self._check_step(observations, where)
        view = None if approach is None else self._check_approach(approach, where)  # before the pose is kept
        self._check_pose(observations, camera_pitch, where)
        step = self._steps
        if view is not None:
            self._approach[str(step)] = view
        atomic.write_image(self._staging / "rgb" / f"{step}.png", rgb)
        _write_npy(self._staging / "semantic" / f"{step}.npy", semantic)
        if depth is not None:
            _write_npy(self._staging / "depth" / f"{step}.npy", depth)
        self._steps += 1

    def finish_episode(self) -> Path:
        """Publish the open episode: rename its folder into place, then list it in ``episodes.json``."""
        if self._record is None:
            raise RecordingError("finish_episode() without an open episode")
        record, staging = self._record, self._staging
        folder = self.root / record["episode_id"]
        if staging is not None:
            if not self._steps:
                self.abort_episode()
                raise RecordingError(f"episode {record['episode_id']!r} has no recorded step: nothing to publish")
            if self._poses:
                atomic.write_json(staging / POSES, {**self.camera, "gps_compass_pitch": self._poses})
            if self._approach:
                atomic.write_json(staging / APPROACH, {"views": self._approach})
            try:
                staging.rename(folder)
            except OSError as exc:
                raise atomic.OutputError(f"cannot publish {folder}: {exc.strerror or exc}") from exc
            with self._index_lock():
                listed = list(self.finished_episodes().values())
                atomic.write_json(self.root / INDEX, {"episodes": [*listed, record]})
        self._record, self._staging = None, None
        return folder

    def abort_episode(self) -> None:
        """Drop the open episode's steps; nothing of it reaches the recording."""
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
        if self._record is not None:
            self._this_run.discard(self._record["episode_id"])
        self._record, self._staging = None, None

    @contextlib.contextmanager
    def episode(self, episode: Any) -> Iterator[FrameRecorder]:
        """``with recorder.episode(ep): ...``: finished on success, dropped on any exception."""
        self.start_episode(episode)
        try:
            yield self
        except BaseException:
            self.abort_episode()
            raise
        self.finish_episode()

    # ------------------------------------------------------------------ helpers
    def _clear_leftovers(self, episode_id: str) -> None:
        """An interrupted earlier run's staging folder, or its folder renamed but never listed."""
        for path in [self.root / episode_id, *self.root.glob(f".{episode_id}.*.staging")]:
            if path.is_dir():
                shutil.rmtree(path)

    @contextlib.contextmanager
    def _index_lock(self) -> Iterator[None]:
        with open(self.root / LOCK, "a") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)

    def _check_step(self, obs: Mapping[str, Any], where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        for key in ("rgb", "semantic"):
            if key not in obs:
                raise RecordingError(f"{where}: the observation has no {key!r} (keys: {sorted(obs)})")
        rgb = np.asarray(obs["rgb"])
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise RecordingError(f"{where}: rgb must be H x W x 3 uint8, got {rgb.shape} {rgb.dtype}")
        size = rgb.shape[:2]
        if self._size is not None and size != self._size:
            raise RecordingError(f"{where}: rgb is {size}, earlier steps were {self._size}")
        self._size = size
        semantic = _frame_of(obs["semantic"], "semantic", size, where)
        if not np.issubdtype(semantic.dtype, np.integer):
            raise RecordingError(f"{where}: semantic must hold integer ids, got {semantic.dtype}")
        self._check_labels(semantic, where)
        depth = obs.get("depth")
        if depth is not None:
            depth = _frame_of(depth, "depth", size, where).astype(np.float32)
            if not np.isfinite(depth).all() or (depth < 0).any():
                raise RecordingError(f"{where}: depth must be finite metres >= 0")
            depth[np.isin(depth, DEPTH_REPLACEMENT_VALUES)] = 0.0
        return rgb, semantic.astype(np.int32), depth

    def _check_pose(self, obs: Mapping[str, Any], pitch: float | None, where: str) -> None:
        has = "gps" in obs and "compass" in obs
        if has != bool(self._poses) and self._steps:
            raise RecordingError(f"{where}: " + ("gps and compass appear after steps without them" if has else
                                                 "no gps or compass, which earlier steps had") +
                                 ": an episode's steps all carry the agent's pose or none does")
        if not has:
            return
        if pitch is None:
            raise RecordingError(f"{where}: gps and compass recorded without camera_pitch: pass record(..., "
                                 "camera_pitch=RADIANS_UP) (0.0 for a level camera), the agent's tilt at this step")
        gps = np.asarray(obs["gps"], np.float64).reshape(-1)
        compass = np.asarray(obs["compass"], np.float64).reshape(-1)
        values = [*gps.tolist(), *compass.tolist(), float(pitch)]
        if gps.size != 2 or compass.size != 1 or not np.isfinite(values).all():
            raise RecordingError(f"{where}: gps must be 2 finite numbers and compass 1 (PIN's sensors), got gps "
                                 f"{gps.tolist()} compass {compass.tolist()} pitch {pitch!r}")
        self._poses.append(values)

    def _check_approach(self, approach: tuple[str, float], where: str) -> list:
        record = self._record or {}
        objects = {str(g["object_id"]) for g in [*record.get("goals", []), *record.get("distractors", [])]}
        object_id, distance = approach
        if str(object_id) not in objects or not (np.isfinite(float(distance)) and float(distance) >= 0):
            raise RecordingError(f"{where}: approach {approach!r} must be (an object of the episode, one of "
                                 f"{sorted(objects)}, and its horizontal distance in metres >= 0)")
        return [str(object_id), float(distance)]

    def _check_labels(self, semantic: np.ndarray, where: str) -> None:
        """Ids from 100000 up are PIN's injected objects (the scene's own ids lie below): only its three exist."""
        ids = set(np.unique(semantic[(semantic >= TARGET_ID) | (semantic < 0)]).tolist())
        unknown = sorted(ids - set(LABELS))
        if unknown:
            raise RecordingError(f"{where}: unknown semantic ids {unknown[:5]}: PIN labels its objects 100000 "
                                 "(target), 100001 (same-category distractor), 100002 (other distractor)")
        absent = sorted(ids - self._labels)
        if absent:
            raise RecordingError(f"{where}: semantic id(s) {absent} show a {LABELS[absent[0]][1]} object, but the "
                                 "episode places none (wrong episode fields?)")


def _frame_of(value: Any, name: str, size: tuple[int, int], where: str) -> np.ndarray:
    """An H x W (or Habitat's H x W x 1) sensor frame of the RGB frame's size, as H x W."""
    arr = np.asarray(value)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.shape != size:
        raise RecordingError(f"{where}: {name} frame is {arr.shape}, the rgb frame is {size}")
    return arr


def _write_npy(path: Path, array: np.ndarray) -> None:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    atomic.write_bytes(path, buffer.getvalue())

