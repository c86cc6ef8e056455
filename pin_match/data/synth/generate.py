"""Orchestration: object instances, episode plans, parallel rendering, one atomic frame-set.

Everything random is drawn from generators seeded by (global seed, name of the thing), and
each worker task starts from an empty pybullet world, so the output bytes depend on the
seed and sizes only, never on the number of workers or their scheduling.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from pin_match.data.compose import FRAME_HEIGHT, FRAME_WIDTH, stable_seed
from pin_match.data.frameset import FrameSet
from pin_match.data.geometry import CameraModel, EpisodeGeometry, FloorMap
from pin_match.data.geometry import Pose as CameraPose
from pin_match.data.synth.clutter import choose_scanned, colour_double
from pin_match.data.synth.objects import ObjectSpec, SynthError, make_objects
from pin_match.data.synth.render import Camera, Light, Renderer, reference_views, vertical_fov
from pin_match.data.synth.scans import PACKAGED_SCANS, ScanFolder
from pin_match.data.synth.scene import Room, make_house, place_objects
from pin_match.data.synth.sensor import develop_view, house_camera, reference_camera
from pin_match.data.synth.shapes import Mesh
from pin_match.data.synth.size import DEFAULT_SIZE, WALKS, SynthSize
from pin_match.data.synth.walk import (
    CAMERA_HEIGHT,
    Goal,
    Pose,
    approach_poses,
    camera_walk,
    exploration_walk,
    floor_map,
    geodesic_lengths,
)
from pin_match.data.writer import Frame, FrameRecord, FrameSetWriter, ImageFile, ObjectOrigin, encode_frame

HFOV = 42.0  # horizontal field of view of the rendered camera, degrees
GENERATOR_VERSION = 8  # 7: houses of rooms, one exploration walk per house that does not know the target; 8: approach
# views of every annotated object after the walk (``walk.approach_poses``)
ROOMS = 3  # rooms per house
TARGETS_PER_HOUSE = 3  # episodes per house: one render of the exploration walk serves each
REACH = 0.9  # metres: the farthest from an agent standing beside it a target or look-alike's centre may be (PIN's 1 m
# success distance less a margin, since the agent stops beside the point it matched, not beside the centre)
SAME_MAX, PIN_SAME = 3, 2.90  # same-category distractors per PIN val episode: at most 3, 2.90 on average


@dataclass(frozen=True)
class HousePlan:
    """What one worker needs to render a house and its episodes: the house's annotated objects, each episode's id and
    the index of its target among them, the walk's kind and step budget, and the clutter."""

    house_id: str
    split: str
    scene_seed: int
    seed: int
    objects: tuple[ObjectSpec, ...]
    episodes: tuple[tuple[str, int], ...]
    frames: int
    walk: str
    staging: str
    clutter: tuple[ObjectSpec, ...] = ()  # scanned products in the house that are background (``clutter``)
    approach_views: bool = True  # render what an agent sees walking up to each annotated object (``approach_poses``)


PlannedHouse = tuple[str, str, list[ObjectSpec], list[tuple[str, int]]]  # house id, split, objects, (episode, target)


def plan_houses(specs: list[ObjectSpec], seed: int, episodes: int) -> list[PlannedHouse]:
    """(house id, split, annotated objects, [(episode id, target index)...]) per house; half the episodes train,
    half val.

    A house holds ``TARGETS_PER_HOUSE`` families, each with one target (an episode) and its look-alikes:
    3 siblings with probability 0.9, else 2 (PIN's val episodes: mean 2.90, at most 3), all of them
    where the family has fewer. An episode's distractors are every other annotated object of its house:
    its family's are its look-alikes, the other families' its other-category objects (PIN's: 4 to 10,
    mean 7.19). Families cycle through a shuffled order of the split's families that have a look-alike in
    it (two members or more), so a split's episodes cover the families evenly.
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
        for h, first in enumerate(range(0, count, TARGETS_PER_HOUSE)):
            objects, targets = [], []
            for i in range(first, first + TARGETS_PER_HOUSE):  # a split's last house is full too, with fewer targets
                category = order[i % len(order)]
                present = [o for o in objects if o.category == category]
                if present:  # a split of few families meets one twice in a house: another of its members is the target
                    taken = {objects[t].object_id for _, t in targets}
                    target = next((o for o in present if o.object_id not in taken), present[0])
                else:
                    same = [s for s in pool if s.category == category]
                    target = same[(i // len(order)) % len(same)]
                    siblings = [s for s in same if s is not target]
                    short = int(rng.random() >= PIN_SAME - (SAME_MAX - 1))  # one episode in ten holds one fewer
                    k = min(SAME_MAX - short, len(siblings))
                    objects += [target] + [siblings[j] for j in sorted(rng.choice(len(siblings), k, replace=False))]
                if i < count:
                    targets.append((f"{split}_{i:03d}", objects.index(target)))
            out.append((f"{split}_house_{h:02d}", split, objects, targets))
    return out


# ------------------------------------------------------------------ worker side
_RENDERER: Renderer | None = None


def _renderer() -> Renderer:
    global _RENDERER
    if _RENDERER is None:
        _RENDERER = Renderer()
    return _RENDERER


def render_object(spec: ObjectSpec, seed: int) -> list[np.ndarray]:
    """The object's reference views, through a reference camera of its own (drawn from the seed and its id)."""
    scan = spec.load()
    rng = np.random.default_rng(stable_seed(seed, "reference", spec.object_id))
    camera = reference_camera(rng)
    return [develop_view(camera, view, rng) for view in reference_views(_renderer(), scan.mesh, scan.texture)]


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


def _episode_geometry(ids: list[str], families: list[str], target: int, house: Room, stage: _Stage, walk: list[Pose],
                      floor: FloorMap) -> EpisodeGeometry:
    """Where the walk starts, every annotated object's centre, the geodesic length to the target and to each of its
    same-family look-alikes, and where an agent can stand."""
    measured = [target] + [k for k, f in enumerate(families) if f == families[target] and k != target]
    lengths = geodesic_lengths(house, stage.obstacles, walk[0][:2], [stage.centres[k][:2] for k in measured])
    x, y, yaw, _ = walk[0]
    return EpisodeGeometry(CameraPose(x, y, 0.0, yaw), lengths[0], dict(zip(ids, stage.centres)),
                           {ids[k]: length for k, length in zip(measured, lengths)}, floor)


def _within_reach(room: Room):
    """Whether an agent standing on the house's floor, beside its furniture, gets within ``REACH`` of a point."""
    standing = floor_map(room, room.footprints)
    return lambda x, y, z: standing.nearest((x, y, z), 0.0) <= REACH


@dataclass
class _Stage:
    """What a house's objects became in the renderer: each annotated object's mask value (its index + 1; clutter stays
    0), how the walk sees it and its body, the floor the walk goes around and each annotated object's centre."""

    lut: np.ndarray  # body id + 1 -> mask value
    looks: list[Goal]
    bodies: list[int]
    obstacles: list[tuple[float, float, float, float]]
    centres: list[tuple[float, float, float]]


def _footprint(mesh: Mesh) -> tuple[float, float, float]:
    """(radius, height, side area): what placement needs of an object."""
    lo, hi = mesh.bounds
    return float(np.hypot(hi[0] - lo[0], hi[1] - lo[1]) / 2), float(hi[2] - lo[2]), mesh.side_area()


def _stage(r: Renderer, house: Room, plan: HousePlan, rng: np.random.Generator) -> _Stage:
    """Place the house's annotated objects (in an order drawn from ``rng``, so which of them is an episode's target
    never decides who gets the best spot), then its clutter: a colour double of each object and the scanned products,
    so the annotated objects have the pick of the surfaces."""
    built = [(scan.mesh, scan.texture) for scan in (s.load() for s in plan.objects)]
    built += [colour_double(mesh, texture, rng) for mesh, texture in built]
    built += [(scan.mesh, scan.texture) for scan in (s.load() for s in plan.clutter)]
    sizes = [_footprint(mesh) for mesh, _ in built]
    family = {c: k for k, c in enumerate(dict.fromkeys(s.category for s in plan.objects))}
    order = [*rng.permutation(len(plan.objects)).tolist(), *range(len(plan.objects), len(built))]
    placed = place_objects(house, [sizes[k] for k in order], rng,
                           [family[plan.objects[k].category] for k in order[:len(plan.objects)]], _within_reach(house))
    spots = [placed[order.index(k)] for k in range(len(built))]  # annotated objects in a drawn order: a target gets
    # no better spot than its look-alikes, as it would if it were placed first
    stage = _Stage(np.zeros(0, np.uint16), [], [], list(house.footprints), [])
    for k, ((mesh, atlas), (x, y, z, yaw)) in enumerate(zip(built, spots)):
        body = r.add(mesh, atlas, (x, y, z), yaw)
        if z < 0.05:  # on the floor or a rug: the camera walks around it
            rad = sizes[k][0]
            stage.obstacles.append((x - rad, y - rad, x + rad, y + rad))
        if k < len(plan.objects):
            stage.bodies.append(body)
            stage.looks.append(_look(mesh, (x, y, z)))
            stage.centres.append((float(x), float(y), float(z + sizes[k][1] / 2)))  # meshes are centred on x, y
    stage.lut = np.zeros(body + 2, np.uint16)  # bodies are numbered in order: the last one added is the highest
    stage.lut[[b + 1 for b in stage.bodies]] = np.arange(1, len(stage.bodies) + 1)
    return stage


EpisodeOutput = tuple[str, list[FrameRecord], EpisodeGeometry]


def render_house(plan: HousePlan) -> list[EpisodeOutput]:
    """A house's episodes, in plan order: each walk rendered once and written for every episode that reads it."""
    r = _renderer()
    r.reset()
    house = make_house(np.random.default_rng(plan.scene_seed), ROOMS)
    for piece in house.pieces:
        r.add(piece.mesh, piece.texture)
    rng = np.random.default_rng(plan.seed)
    stage = _stage(r, house, plan, rng)
    light = episode_light(rng)
    camera = house_camera(rng)
    vfov = vertical_fov(HFOV, FRAME_WIDTH, FRAME_HEIGHT)
    ids = [s.object_id for s in plan.objects]
    families = [s.category for s in plan.objects]

    def sight(look: Goal, pose: Pose) -> float:
        """Pixels of the object seen from ``pose``, from a render at a quarter of the frame's size."""
        pixels = r.render(_camera(pose), FRAME_WIDTH // 4, FRAME_HEIGHT // 4, vfov, light)[1]
        return 16.0 * float((pixels == stage.bodies[stage.looks.index(look)]).sum())

    if plan.walk == "explore":
        walk = exploration_walk(house, stage.obstacles, [c[:2] for c in stage.centres], plan.frames, rng)
        groups = [(walk, list(plan.episodes))]
    else:
        groups = [(camera_walk(house, stage.obstacles, stage.looks[t],
                               [stage.looks[k] for k, f in enumerate(families) if f == families[t] and k != t],
                               plan.frames, rng, sight), [(episode_id, t)]) for episode_id, t in plan.episodes]
    floor = floor_map(house, stage.obstacles)
    out = {}
    for walk, episodes in groups:
        views = [(pose, (ids[k], distance)) for k, centre in enumerate(stage.centres) if plan.approach_views
                 for pose, distance in approach_poses(floor, walk, centre)]
        shots = [(pose, None) for pose in walk] + views  # the approach views' steps follow the walk's
        records = _render_walk(r, shots, stage, light, camera, plan, episodes)
        for episode_id, t in episodes:
            out[episode_id] = (episode_id, records[episode_id],
                               _episode_geometry(ids, families, t, house, stage, walk, floor))
    return [out[episode_id] for episode_id, _ in plan.episodes]


def _render_walk(r: Renderer, shots: list[tuple[Pose, tuple[str, float] | None]], stage: _Stage, light: Light, camera,
                 plan: HousePlan, episodes: list[tuple[str, int]]) -> dict[str, list[FrameRecord]]:
    """Each pose rendered and developed once, then written for every episode in ``episodes`` with its own roles; a
    shot's second part marks an approach view (``Frame.approach``)."""
    vfov = vertical_fov(HFOV, FRAME_WIDTH, FRAME_HEIGHT)
    legends = {episode_id: {k + 1: (s.object_id, "target" if k == t else "same_category"
                                    if s.category == plan.objects[t].category else "other")
                            for k, s in enumerate(plan.objects)} for episode_id, t in episodes}
    records: dict[str, list[FrameRecord]] = {episode_id: [] for episode_id, _ in episodes}
    for step, (pose, approach) in enumerate(shots):
        rgb, bodies, depth = r.render(_camera(pose), FRAME_WIDTH, FRAME_HEIGHT, vfov, light)
        noise = np.random.default_rng(stable_seed(plan.seed, "noise", step))
        image = camera.develop(rgb, noise)
        stored = ImageFile(".jpg", camera.encode(image, noise))  # stored: the camera's JPEG
        mask = stage.lut[bodies + 1]
        for episode_id, legend in legends.items():
            frame = Frame(image, mask, legend, depth, _camera_pose(pose), approach)
            records[episode_id].append(encode_frame(plan.staging, episode_id, step, frame, stored))
    return records


# ------------------------------------------------------------------ entry point
def _check(size: SynthSize) -> None:
    if size.episodes < 2:
        raise SynthError(f"episodes must be at least 2 (one train, one val), got {size.episodes}")
    if size.frames_per_episode < 1:
        raise SynthError(f"frames_per_episode must be positive, got {size.frames_per_episode}")
    if not size.splits or set(size.splits) - {"train", "val"}:
        raise SynthError(f"splits {list(size.splits)}: render 'train', 'val' or both")
    if size.walk not in WALKS:
        raise SynthError(f"walk {size.walk!r}: choose one of {', '.join(WALKS)}")


def generate(out: str | Path, size: SynthSize = DEFAULT_SIZE, *, scans: str | Path | None = None,
             workers: int | None = None, overwrite: bool = False, progress: bool = False) -> FrameSet:
    """Write a complete synthetic PIN-like frame-set to ``out`` and return it loaded.

    ``size.splits`` renders only some splits (the demo's val split, when its sigmas are shipped):
    every episode is planned as in the whole set, so a split rendered alone has the whole set's bytes.

    ``scans`` is a scan folder (``pin-match data prepare gso``; default: the scans shipped with
    pin_match) whose ``families.csv`` names the families. ``workers`` processes (default: all
    cores) render reference views and episodes; the result is byte-identical for any number of
    workers. ``progress`` shows a bar per stage.
    """
    from tqdm import tqdm

    seed = size.seed
    _check(size)
    folder = ScanFolder.open(PACKAGED_SCANS if scans is None else scans)
    specs = make_objects(folder, size.objects_per_family)
    houses = [h for h in plan_houses(specs, seed, size.episodes) if h[1] in size.splits]
    in_houses = {o.object_id for _, _, objs, _ in houses for o in objs}
    rendered_specs = [s for s in specs if s.object_id in in_houses]  # a family no house holds needs no references
    provenance = dict(generator="pin_match.data.synth", version=GENERATOR_VERSION, seed=seed, episodes=size.episodes,
                      objects_per_family=size.objects_per_family, frames_per_episode=size.frames_per_episode,
                      walk=size.walk, approach_views=size.approach_views, rooms=ROOMS,
                      targets_per_house=TARGETS_PER_HOUSE,
                      scans="packaged" if scans is None else str(Path(scans).resolve()),
                      renderer="pybullet TinyRenderer", frame_size=[FRAME_HEIGHT, FRAME_WIDTH], hfov=HFOV,
                      camera_height=CAMERA_HEIGHT)
    if set(size.splits) != {"train", "val"}:  # planned as the whole set, so its episodes are the whole set's bytes
        provenance["splits"] = sorted(size.splits)
    writer = FrameSetWriter(out, Path(out).name, overwrite=overwrite, provenance=provenance,
                            camera=CameraModel(HFOV))
    with writer:
        workers = max(1, workers or os.cpu_count() or 1)
        pool = mp.get_context("spawn").Pool(workers) if workers > 1 else None
        try:
            imap = pool.imap if pool else map
            rendered = tqdm(imap(partial(render_object, seed=seed), rendered_specs), total=len(rendered_specs),
                            desc="render objects", unit="object", disable=not progress, dynamic_ncols=True)
            for spec, views in zip(rendered_specs, rendered):
                writer.add_object(spec.object_id, spec.category, spec.split, views, list(spec.descriptions),
                                  origin=ObjectOrigin(spec.source, spec.licence))
            plans = []
            for house_id, split, objs, episodes in houses:
                for episode_id, t in episodes:
                    writer.add_episode(episode_id, split, house_id, objs[t].object_id,
                                       [o.object_id for k, o in enumerate(objs) if k != t])
                clutter = choose_scanned([s for s in specs if s.split == split], objs,
                                         np.random.default_rng(stable_seed(seed, "clutter", house_id)))
                plans.append(HousePlan(house_id, split, stable_seed(seed, "scene", house_id),
                                       stable_seed(seed, "house", house_id), tuple(objs), tuple(episodes),
                                       size.frames_per_episode, size.walk, str(writer.staging), tuple(clutter),
                                       size.approach_views))
            for episodes in tqdm(imap(render_house, plans), total=len(plans), desc="render houses", unit="house",
                                 disable=not progress, dynamic_ncols=True):
                for episode_id, records, geometry in episodes:
                    writer.add_geometry(episode_id, geometry)
                    for rec in records:
                        writer.add_frame_record(rec)
        finally:
            if pool:
                pool.close()
                pool.join()
        return writer.close()
