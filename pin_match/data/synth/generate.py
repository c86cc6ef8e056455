"""Orchestration: object instances, episode plans, parallel rendering, one atomic frame-set.

Everything random is drawn from generators seeded by (global seed, name of the thing), and
each worker task starts from an empty pybullet world, so the output bytes depend on the
seed and sizes only, never on the number of workers or their scheduling.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pin_match.data.compose import FRAME_HEIGHT, FRAME_WIDTH, stable_seed
from pin_match.data.frameset import FrameSet
from pin_match.data.geometry import CameraModel, EpisodeGeometry
from pin_match.data.geometry import Pose as CameraPose
from pin_match.data.synth.objects import ObjectSpec, SynthError, make_objects
from pin_match.data.synth.render import Camera, Light, Renderer, reference_views, vertical_fov
from pin_match.data.synth.scans import PACKAGED_SCANS, ScanFolder
from pin_match.data.synth.scene import make_room, place_objects
from pin_match.data.synth.shapes import Mesh
from pin_match.data.synth.size import DEFAULT_SIZE, SynthSize
from pin_match.data.synth.walk import CAMERA_HEIGHT, Goal, Pose, camera_walk, geodesic_lengths
from pin_match.data.writer import Frame, FrameRecord, FrameSetWriter, ObjectOrigin, encode_frame

HFOV = 42.0  # horizontal field of view of the rendered camera, degrees
GENERATOR_VERSION = 4  # 4: camera poses, object positions and geodesic lengths recorded (frames unchanged)


@dataclass(frozen=True)
class EpisodePlan:
    """What one worker needs to render an episode: its objects (target first) with their roles."""

    episode_id: str
    split: str
    scene_id: str
    scene_seed: int
    seed: int
    objects: tuple[ObjectSpec, ...]
    roles: tuple[str, ...]
    frames: int
    staging: str


def plan_episodes(specs: list[ObjectSpec], seed: int, episodes: int) -> list[tuple[str, str, str, list[ObjectSpec]]]:
    """(episode id, split, scene id, [target, distractors...]) per episode; half train, half val.

    Targets cycle through a shuffled order of the split's families that have a look-alike in it
    (two members or more), so a split's episodes cover the families evenly; same-category
    distractors are up to 3 siblings (3 most of the time, as PIN's 2.90 average), other-category
    distractors 5 to 10 instances of other families.
    """
    out = []
    n_val = episodes // 2
    for split, count in (("train", episodes - n_val), ("val", n_val)):
        pool = [s for s in specs if s.split == split]
        families = sorted({s.category for s in pool if sum(o.category == s.category for o in pool) > 1})
        if not families:
            raise SynthError(f"no family has two {split} instances: an episode needs a target and a look-alike")
        rng = np.random.default_rng(stable_seed(seed, "episodes", split))
        order = [families[k] for k in rng.permutation(len(families))]
        n_scenes = max(1, (count + 1) // 2)
        for i in range(count):
            category = order[i % len(order)]
            same = [s for s in pool if s.category == category]
            target = same[(i // len(order)) % len(same)]
            siblings = [s for s in same if s is not target]
            k = min(3, len(siblings))
            if k > 1 and rng.random() < 0.25:
                k = int(rng.integers(1, k + 1))
            others = [s for s in pool if s.category != category]
            n_other = min(len(others), int(rng.integers(5, 11)))
            chosen = [siblings[j] for j in sorted(rng.choice(len(siblings), k, replace=False))]
            chosen += [others[j] for j in sorted(rng.choice(len(others), n_other, replace=False))]
            out.append((f"{split}_{i:03d}", split, f"{split}_scene_{i % n_scenes:02d}", [target, *chosen]))
    return out


# ------------------------------------------------------------------ worker side
_RENDERER: Renderer | None = None


def _renderer() -> Renderer:
    global _RENDERER
    if _RENDERER is None:
        _RENDERER = Renderer()
    return _RENDERER


def render_object(spec: ObjectSpec) -> list[np.ndarray]:
    scan = spec.load()
    return reference_views(_renderer(), scan.mesh, scan.texture)


def episode_light(rng: np.random.Generator) -> Light:
    """Direction, colour temperature and ambient/diffuse balance vary per episode.

    Indoor light is mostly diffuse (PIN's scanned houses carry it baked in): ambient stays at 0.6
    or more, so a face turned from the single light keeps most of its colour. With ambient down to
    0.4 (generator version 2) a scanned box's front could render near black beside its bright
    reference views.
    """
    warm = rng.uniform(-1, 1)
    colour = (1.0, 1.0 - 0.06 * abs(warm) * (warm > 0), 1.0 - 0.12 * warm) if warm > 0 else (1.0 + 0.1 * warm, 1.0,
                                                                                                1.0)
    return Light(direction=(float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), float(rng.uniform(0.6, 2.0))),
                 colour=tuple(float(c) for c in colour), ambient=float(rng.uniform(0.6, 0.75)),
                 diffuse=float(rng.uniform(0.25, 0.4)), specular=float(rng.uniform(0.02, 0.1)))


def _camera_look(image: np.ndarray, gain: float, rng: np.random.Generator) -> np.ndarray:
    """A camera's imperfections on the rendered image: exposure, slight lens softness, sensor noise.

    Only the RGB is touched; masks and depth stay the renderer's exact buffers.
    """
    img = cv2.GaussianBlur(image.astype(np.float32), (0, 0), 0.6) * gain
    img += rng.normal(0, 2.5, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _camera(pose: Pose) -> Camera:
    """The camera of a walk pose (x, y, yaw, pitch) at PIN's camera height."""
    x, y, yaw, pitch = pose
    ahead = (np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch))
    return Camera((x, y, CAMERA_HEIGHT), (x + ahead[0], y + ahead[1], CAMERA_HEIGHT + ahead[2]))


def _look(mesh: Mesh, at: tuple[float, float, float]) -> Goal:
    """An object as the walk sees it: its centre and its side-on area."""
    height = float(mesh.bounds[1][2] - mesh.bounds[0][2])
    return Goal(at[0], at[1], at[2] + height / 2, mesh.side_area())


def _camera_pose(pose: Pose) -> CameraPose:
    x, y, yaw, pitch = pose
    return CameraPose(x, y, CAMERA_HEIGHT, yaw, pitch)


def _episode_geometry(plan: EpisodePlan, room, obstacles, walk: list[Pose],
                      centres: list[tuple[float, float, float]]) -> EpisodeGeometry:
    """Where the walk starts, every placed object's centre, and the geodesic length to the target and to each
    same-category look-alike."""
    ids = [spec.object_id for spec in plan.objects]
    measured = [k for k, role in enumerate(plan.roles) if role in ("target", "same_category")]
    lengths = geodesic_lengths(room, obstacles, walk[0][:2], [centres[k][:2] for k in measured])
    x, y, yaw, _ = walk[0]
    return EpisodeGeometry(CameraPose(x, y, 0.0, yaw), lengths[0], dict(zip(ids, centres)),
                           {ids[k]: length for k, length in zip(measured, lengths)})


def render_episode(plan: EpisodePlan) -> tuple[list[FrameRecord], EpisodeGeometry]:
    r = _renderer()
    r.reset()
    room = make_room(np.random.default_rng(plan.scene_seed))
    for piece in room.pieces:
        r.add(piece.mesh, piece.texture)
    rng = np.random.default_rng(plan.seed)
    built = [(scan.mesh, scan.texture) for scan in (s.load() for s in plan.objects)]
    sizes = []
    for mesh, _ in built:
        lo, hi = mesh.bounds
        sizes.append((float(np.hypot(hi[0] - lo[0], hi[1] - lo[1]) / 2), float(hi[2] - lo[2]), mesh.side_area()))
    lookalikes = frozenset(k for k, role in enumerate(plan.roles) if role == "same_category")
    spots = place_objects(room, sizes, rng, lookalikes)
    lut = np.zeros(1, np.uint16)
    legend = {}
    looks: dict[str, list[Goal]] = {"target": [], "same_category": []}
    bodies: dict[Goal, int] = {}
    obstacles = list(room.footprints)
    centres = []
    for k, ((mesh, atlas), (x, y, z, yaw), spec, role) in enumerate(zip(built, spots, plan.objects, plan.roles)):
        body = r.add(mesh, atlas, (x, y, z), yaw)
        centres.append((float(x), float(y), float(z + sizes[k][1] / 2)))  # meshes are centred on x, y
        if body + 2 > len(lut):
            lut = np.concatenate([lut, np.zeros(body + 2 - len(lut), np.uint16)])
        lut[body + 1] = k + 1
        legend[k + 1] = (spec.object_id, role)
        if role in looks:
            looks[role].append(_look(mesh, (x, y, z)))
            bodies[looks[role][-1]] = body
        if z < 0.05:  # on the floor or a rug: the camera walks around it
            rad = sizes[k][0]
            obstacles.append((x - rad, y - rad, x + rad, y + rad))
    light = episode_light(rng)
    gain = float(rng.uniform(0.9, 1.1))
    vfov = vertical_fov(HFOV, FRAME_WIDTH, FRAME_HEIGHT)
    records = []

    def sight(look: Goal, pose: Pose) -> float:
        """Pixels of the object seen from ``pose``, from a render at a quarter of the frame's size."""
        ids = r.render(_camera(pose), FRAME_WIDTH // 4, FRAME_HEIGHT // 4, vfov, light)[1]
        return 16.0 * float((ids == bodies[look]).sum())

    walk = camera_walk(room, obstacles, looks["target"][0], looks["same_category"], plan.frames, rng, sight)
    for step, pose in enumerate(walk):
        rgb, ids, depth = r.render(_camera(pose), FRAME_WIDTH, FRAME_HEIGHT, vfov, light)
        mask = lut[np.clip(ids + 1, 0, len(lut) - 1)]
        image = _camera_look(rgb, gain, np.random.default_rng(stable_seed(plan.seed, "noise", step)))
        records.append(encode_frame(plan.staging, plan.episode_id, step,
                                    Frame(image, mask, legend, depth, _camera_pose(pose))))
    return records, _episode_geometry(plan, room, obstacles, walk, centres)


# ------------------------------------------------------------------ entry point
def generate(out: str | Path, size: SynthSize = DEFAULT_SIZE, *, scans: str | Path | None = None,
             workers: int | None = None, overwrite: bool = False, progress: bool = False) -> FrameSet:
    """Write a complete synthetic PIN-like frame-set to ``out`` and return it loaded.

    ``scans`` is a scan folder (``pin-match data prepare gso``; default: the scans shipped with
    pin_match) whose ``families.csv`` names the families. ``workers`` processes (default: all
    cores) render reference views and episodes; the result is byte-identical for any number of
    workers. ``progress`` shows a bar per stage.
    """
    from tqdm import tqdm

    seed = size.seed
    if size.episodes < 2:
        raise SynthError(f"episodes must be at least 2 (one train, one val), got {size.episodes}")
    if size.frames_per_episode < 1:
        raise SynthError(f"frames_per_episode must be positive, got {size.frames_per_episode}")
    folder = ScanFolder.open(PACKAGED_SCANS if scans is None else scans)
    specs = make_objects(folder, size.objects_per_family)
    provenance = dict(generator="pin_match.data.synth", version=GENERATOR_VERSION, seed=seed, episodes=size.episodes,
                      objects_per_family=size.objects_per_family, frames_per_episode=size.frames_per_episode,
                      scans="packaged" if scans is None else str(Path(scans).resolve()),
                      renderer="pybullet TinyRenderer", frame_size=[FRAME_HEIGHT, FRAME_WIDTH], hfov=HFOV,
                      camera_height=CAMERA_HEIGHT)
    writer = FrameSetWriter(out, Path(out).name, overwrite=overwrite, provenance=provenance,
                            camera=CameraModel(HFOV))
    with writer:
        workers = max(1, workers or os.cpu_count() or 1)
        pool = mp.get_context("spawn").Pool(workers) if workers > 1 else None
        try:
            imap = pool.imap if pool else map
            rendered = tqdm(imap(render_object, specs), total=len(specs), desc="render objects", unit="object",
                            disable=not progress, dynamic_ncols=True)
            for spec, views in zip(specs, rendered):
                writer.add_object(spec.object_id, spec.category, spec.split, views, list(spec.descriptions),
                                  origin=ObjectOrigin(spec.source, spec.licence))
            plans = []
            for episode_id, split, scene_id, objs in plan_episodes(specs, seed, size.episodes):
                writer.add_episode(episode_id, split, scene_id, objs[0].object_id, [o.object_id for o in objs[1:]])
                roles = writer.roles(episode_id)
                plans.append(EpisodePlan(episode_id, split, scene_id, stable_seed(seed, "scene", scene_id),
                                         stable_seed(seed, "episode", episode_id),
                                         tuple(objs), tuple(roles[o.object_id] for o in objs), size.frames_per_episode,
                                         str(writer.staging)))
            for plan, (records, geometry) in zip(plans, tqdm(imap(render_episode, plans), total=len(plans),
                                                             desc="render episodes", unit="episode",
                                                             disable=not progress, dynamic_ncols=True)):
                writer.add_geometry(plan.episode_id, geometry)
                for rec in records:
                    writer.add_frame_record(rec)
        finally:
            if pool:
                pool.close()
                pool.join()
        return writer.close()
