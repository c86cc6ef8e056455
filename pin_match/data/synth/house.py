"""A planned house staged in the renderer: its rooms, its objects on their spots, its light and its camera.

Generation renders the house's walk through it (``generate.render_house``); the closed loop renders what the
agent sees walking up to a candidate, on demand, long after the set was written (``walkups``). Both go through
``HouseWorld.build``, which draws everything from the plan's seeds in one order, so a house staged again is the
house the walk saw, bit for bit, as long as this install is the one that built it (``walkups.definition``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pin_match.data.agent import CAMERA_HEIGHT, FRAME_HEIGHT, FRAME_WIDTH, HFOV_DEG
from pin_match.data.compose import stable_seed
from pin_match.data.geometry import Pose as CameraPose
from pin_match.data.synth.clutter import colour_double
from pin_match.data.synth.objects import ObjectSpec
from pin_match.data.synth.placing import place_objects
from pin_match.data.synth.render import Camera, Light, Renderer, vertical_fov
from pin_match.data.synth.scene import Room, make_house
from pin_match.data.synth.sensor import Sensor, house_camera
from pin_match.data.synth.shapes import Mesh
from pin_match.data.synth.walk import Goal, Pose, floor_map
from pin_match.data.writer import Frame, ImageFile

REACH = 0.9  # metres: the farthest from an agent standing beside it a target or look-alike's centre may be (PIN's 1 m
# success distance less a margin, since the agent stops beside the point it matched, not beside the centre)


@dataclass(frozen=True)
class HousePlan:
    """What one worker needs to render a house and its episodes: its rooms, the house's annotated objects, each
    episode's id and the index of its target among them, the walk's kind and step budget, and the clutter."""

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
    rooms: int = 3

    def legend(self, target: int) -> dict[int, tuple[str, str]]:
        """Mask value -> (object id, role) for the episode whose target is object ``target``."""
        return {k + 1: (s.object_id, "target" if k == target else "same_category"
                        if s.category == self.objects[target].category else "other")
                for k, s in enumerate(self.objects)}


_RENDERER: Renderer | None = None


def renderer() -> Renderer:
    """This process's renderer (pybullet's DIRECT clients are per process)."""
    global _RENDERER
    if _RENDERER is None:
        _RENDERER = Renderer()
    return _RENDERER


def episode_light(rng: np.random.Generator) -> Light:
    """Direction, colour temperature and ambient/diffuse balance vary per house.

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


def camera_of(pose: Pose) -> Camera:
    """The camera of a view (x, y, yaw, pitch) at PIN's camera height."""
    x, y, yaw, pitch = pose
    ahead = (np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch))
    return Camera((x, y, CAMERA_HEIGHT), (x + ahead[0], y + ahead[1], CAMERA_HEIGHT + ahead[2]))


def camera_pose(pose: Pose) -> CameraPose:
    x, y, yaw, pitch = pose
    return CameraPose(x, y, CAMERA_HEIGHT, yaw, pitch)


@dataclass
class Stage:
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


def _look(mesh: Mesh, at: tuple[float, float, float]) -> Goal:
    """An object as the walk sees it: its centre and its side-on area."""
    height = float(mesh.bounds[1][2] - mesh.bounds[0][2])
    return Goal(at[0], at[1], at[2] + height / 2, mesh.side_area())


def _within_reach(room: Room):
    """Whether an agent standing on the house's floor, beside its furniture, gets within ``REACH`` of a point."""
    standing = floor_map(room, room.footprints)
    return lambda x, y, z: standing.nearest((x, y, z), 0.0) <= REACH


def _stage(r: Renderer, house: Room, plan: HousePlan, rng: np.random.Generator) -> Stage:
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
    stage = Stage(np.zeros(0, np.uint16), [], [], list(house.footprints), [])
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


@dataclass
class HouseWorld:
    """A house staged in this process's renderer, with its light and its camera's sensor; ``rng`` is left where the
    walk starts drawing from it."""

    plan: HousePlan
    house: Room
    stage: Stage
    light: Light
    sensor: Sensor
    rng: np.random.Generator

    @classmethod
    def build(cls, plan: HousePlan) -> HouseWorld:
        r = renderer()
        r.reset()
        house = make_house(np.random.default_rng(plan.scene_seed), plan.rooms)
        for piece in house.pieces:
            r.add(piece.mesh, piece.texture)
        rng = np.random.default_rng(plan.seed)
        stage = _stage(r, house, plan, rng)
        light = episode_light(rng)
        return cls(plan, house, stage, light, house_camera(rng), rng)

    def sight(self, look: Goal, pose: Pose) -> float:
        """Pixels of the object seen from ``pose``, from a render at a quarter of the frame's size."""
        pixels = renderer().render(camera_of(pose), FRAME_WIDTH // 4, FRAME_HEIGHT // 4, _VFOV, self.light)[1]
        return 16.0 * float((pixels == self.stage.bodies[self.stage.looks.index(look)]).sum())

    def shot(self, pose: Pose, noise: tuple) -> tuple[Frame, ImageFile]:
        """The view from ``pose`` as the camera stores it (its JPEG) with the renderer's exact mask and depth; the
        frame's noise is drawn from the plan's seed and ``noise`` (a step, or a walk-up view's name). The frame's
        legend is left empty: each episode gives its own (``HousePlan.legend``)."""
        rgb, bodies, depth = renderer().render(camera_of(pose), FRAME_WIDTH, FRAME_HEIGHT, _VFOV, self.light)
        rng = np.random.default_rng(stable_seed(self.plan.seed, *noise))
        image = self.sensor.develop(rgb, rng)
        stored = ImageFile(".jpg", self.sensor.encode(image, rng))
        return Frame(image, self.stage.lut[bodies + 1], {}, depth, camera_pose(pose)), stored


_VFOV = vertical_fov(HFOV_DEG, FRAME_WIDTH, FRAME_HEIGHT)
