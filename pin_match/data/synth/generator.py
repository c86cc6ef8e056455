"""Orchestration: object instances, episode plans, parallel rendering, one atomic frame-set.

Everything random is drawn from generators seeded by (global seed, name of the thing), and
each worker task starts from an empty pybullet world, so the output bytes depend on the
seed and sizes only, never on the number of workers or their scheduling.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

from pin_match.data.agent import CAMERA_HEIGHT, FRAME_HEIGHT, FRAME_WIDTH, HFOV_DEG
from pin_match.data.compose import stable_seed
from pin_match.data.digest import files_digest
from pin_match.data.frameset import FrameSet
from pin_match.data.geometry import CameraModel, EpisodeGeometry, FloorMap
from pin_match.data.geometry import Pose as CameraPose
from pin_match.data.synth.clutter import choose_scanned
from pin_match.data.synth.house import HousePlan, HouseWorld, Stage, renderer
from pin_match.data.synth.objects import ObjectSpec, SynthError, make_objects
from pin_match.data.synth.render import reference_views
from pin_match.data.synth.scans import PACKAGED_SCANS, ScanFolder
from pin_match.data.synth.scene import Room
from pin_match.data.synth.sensor import develop_view, reference_camera
from pin_match.data.synth.size import DEFAULT_SIZE, DEFINITION_READS, GENERATOR, WALKS, SynthSize
from pin_match.data.synth.tour import exploration_walk
from pin_match.data.synth.walk import Pose, camera_walk, floor_map
from pin_match.data.writer import FrameRecord, FrameSetWriter, ObjectOrigin, encode_frame

GENERATOR_VERSION = 10  # 8: approach views of every annotated object after the walk; 9: tours of the whole house,
# no approach views (the closed loop renders each walk-up on demand: ``walkups``); 10: geodesic lengths on the
# floor map (``FloorMap.geodesic``), every walk on one path engine (``data.paths``: shortest paths where the walker
# went breadth-first), a tour's headings kept ``TURNED`` inside the view, the camera's constants from ``data.agent``,
# the walk that seeks the target named ``seek``
TARGETS_PER_HOUSE = 3  # episodes per house: one render of the exploration walk serves each
SAME_MAX, PIN_SAME = 3, 2.90  # same-category distractors per PIN val episode: at most 3, 2.90 on average


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


def plan_set(size: SynthSize, folder: ScanFolder, staging: str = "") -> tuple[list[ObjectSpec], list[HousePlan]]:
    """The objects whose references a set of ``size`` renders (those its houses hold) and its houses' plans, in the
    order they are rendered: what ``generate`` writes and ``walkups.SynthHouses`` stages again."""
    specs = make_objects(folder, size.objects_per_family)
    houses = [h for h in plan_houses(specs, size.seed, size.episodes) if h[1] in size.splits]
    in_houses = {o.object_id for _, _, objs, _ in houses for o in objs}
    plans = []
    for house_id, split, objs, episodes in houses:
        clutter = choose_scanned([s for s in specs if s.split == split], objs,
                                 np.random.default_rng(stable_seed(size.seed, "clutter", house_id)))
        plans.append(HousePlan(house_id, split, stable_seed(size.seed, "scene", house_id),
                               stable_seed(size.seed, "house", house_id), tuple(objs), tuple(episodes),
                               size.frames_per_episode, size.walk, staging, tuple(clutter), size.rooms))
    return [s for s in specs if s.object_id in in_houses], plans


def definition(folder: ScanFolder) -> str:
    """The digest of what makes a house from its plan: the generator's version, the scans' files and the modules
    that build, stage and render it. A set whose provenance names another cannot be staged again by this install
    (``walkups.SynthHouses``): its houses would not be the ones its walks saw."""
    package = Path(__file__).resolve().parents[2]
    return files_digest({"version": str(GENERATOR_VERSION)},
                        [(package, DEFINITION_READS), (Path(folder.root), ("**/*",))])


# ------------------------------------------------------------------ worker side
def render_object(spec: ObjectSpec, seed: int) -> list[np.ndarray]:
    """The object's reference views, through a reference camera of its own (drawn from the seed and its id)."""
    scan = spec.load()
    rng = np.random.default_rng(stable_seed(seed, "reference", spec.object_id))
    camera = reference_camera(rng)
    return [develop_view(camera, view, rng) for view in reference_views(renderer(), scan.mesh, scan.texture)]


def _episode_geometry(ids: list[str], families: list[str], target: int, house: Room, stage: Stage, walk: list[Pose],
                      floor: FloorMap) -> EpisodeGeometry:
    """Where the walk starts, every annotated object's centre, the geodesic length to the target and to each of its
    same-family look-alikes, and where an agent can stand."""
    measured = [target] + [k for k, f in enumerate(families) if f == families[target] and k != target]
    lengths = [floor.geodesic(walk[0][:2], stage.centres[k][:2]) for k in measured]
    x, y, yaw, _ = walk[0]
    return EpisodeGeometry(CameraPose(x, y, 0.0, yaw), lengths[0], dict(zip(ids, stage.centres)),
                           {ids[k]: length for k, length in zip(measured, lengths)}, floor)


EpisodeOutput = tuple[str, list[FrameRecord], EpisodeGeometry]


def render_house(plan: HousePlan, part: tuple[int, int] = (0, 1)) -> list[EpisodeOutput]:
    """A house's episodes, in plan order: each walk rendered once and written for every episode that reads it; with
    ``part`` (k, n) only the k-th of n runs of each walk's steps. Every part stages the house from its plan, the same
    house bit for bit, so a house split over workers gives the bytes it gives whole."""
    world = HouseWorld.build(plan)
    house, stage, rng = world.house, world.stage, world.rng
    ids = [s.object_id for s in plan.objects]
    families = [s.category for s in plan.objects]
    if plan.walk == "explore":
        walk = exploration_walk(house, stage.obstacles, [c[:2] for c in stage.centres], plan.frames, rng)
        groups = [(walk, list(plan.episodes))]
    else:
        groups = [(camera_walk(house, stage.obstacles, stage.looks[t],
                               [stage.looks[k] for k, f in enumerate(families) if f == families[t] and k != t],
                               plan.frames, rng, world.sight), [(episode_id, t)]) for episode_id, t in plan.episodes]
    floor = floor_map(house, stage.obstacles)
    out = {}
    k, n = part
    for walk, episodes in groups:
        records = _render_walk(world, walk[:len(walk) * (k + 1) // n], episodes, len(walk) * k // n)
        for episode_id, t in episodes:
            out[episode_id] = (episode_id, records[episode_id],
                               _episode_geometry(ids, families, t, house, stage, walk, floor))
    return [out[episode_id] for episode_id, _ in plan.episodes]


def _render_walk(world: HouseWorld, walk: list[Pose], episodes: list[tuple[str, int]],
                 first: int = 0) -> dict[str, list[FrameRecord]]:
    """Each pose from step ``first`` on rendered and developed once, then written for every episode in ``episodes``
    with its own roles."""
    legends = {episode_id: world.plan.legend(t) for episode_id, t in episodes}
    records: dict[str, list[FrameRecord]] = {episode_id: [] for episode_id, _ in episodes}
    for step, pose in enumerate(walk[first:], start=first):
        frame, stored = world.shot(pose, ("noise", step))
        for episode_id, legend in legends.items():
            records[episode_id].append(encode_frame(world.plan.staging, episode_id, step, replace(frame, legend=legend),
                                                    stored))
    return records


def _render_part(task: tuple[HousePlan, tuple[int, int]]) -> list[EpisodeOutput]:
    return render_house(*task)


# ------------------------------------------------------------------ entry point
def _check(size: SynthSize) -> None:
    if size.episodes < 2:
        raise SynthError(f"episodes must be at least 2 (one train, one val), got {size.episodes}")
    if size.rooms < 1:
        raise SynthError(f"rooms must be at least 1, got {size.rooms}")
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
    workers. ``progress`` shows a bar per stage. The provenance names the set's ``definition``, so the
    closed loop can stage its houses again to render walk-ups (``walkups``).
    """
    from tqdm import tqdm

    _check(size)
    folder = ScanFolder.open(PACKAGED_SCANS if scans is None else scans)
    provenance = dict(generator=GENERATOR, version=GENERATOR_VERSION, seed=size.seed,
                      episodes=size.episodes, objects_per_family=size.objects_per_family,
                      frames_per_episode=size.frames_per_episode, walk=size.walk, rooms=size.rooms,
                      targets_per_house=TARGETS_PER_HOUSE,
                      scans="packaged" if scans is None else str(Path(scans).resolve()),
                      renderer="pybullet TinyRenderer", frame_size=[FRAME_HEIGHT, FRAME_WIDTH], hfov=HFOV_DEG,
                      camera_height=CAMERA_HEIGHT, definition=definition(folder))
    if set(size.splits) != {"train", "val"}:  # planned as the whole set, so its episodes are the whole set's bytes
        provenance["splits"] = sorted(size.splits)
    writer = FrameSetWriter(out, Path(out).name, overwrite=overwrite, provenance=provenance,
                            camera=CameraModel(HFOV_DEG))
    with writer:
        specs, plans = plan_set(size, folder, str(writer.staging))
        workers = max(1, workers or os.cpu_count() or 1)
        pool = mp.get_context("spawn").Pool(workers) if workers > 1 else None
        try:
            imap = pool.imap if pool else map
            rendered = tqdm(imap(partial(render_object, seed=size.seed), specs), total=len(specs),
                            desc="render objects", unit="object", disable=not progress, dynamic_ncols=True)
            for spec, views in zip(specs, rendered):
                writer.add_object(spec.object_id, spec.category, spec.split, views, list(spec.descriptions),
                                  origin=ObjectOrigin(spec.source, spec.licence))
            for plan in plans:
                for episode_id, t in plan.episodes:
                    writer.add_episode(episode_id, plan.split, plan.house_id, plan.objects[t].object_id,
                                       [o.object_id for k, o in enumerate(plan.objects) if k != t])
            parts = max(1, workers // max(1, len(plans)))  # fewer houses than workers: each split over them
            rendered_parts = imap(_render_part, [(plan, (k, parts)) for plan in plans for k in range(parts)])
            for _ in tqdm(plans, desc="render houses", unit="house", disable=not progress, dynamic_ncols=True):
                house = [next(rendered_parts) for _ in range(parts)]
                for i, (episode_id, _, geometry) in enumerate(house[0]):
                    writer.add_geometry(episode_id, geometry)
                    for rec in (rec for episodes in house for rec in episodes[i][1]):
                        writer.add_frame_record(rec)
        finally:
            if pool:
                pool.close()
                pool.join()
        return writer.close()
