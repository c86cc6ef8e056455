"""pybullet's TinyRenderer as a CPU rasteriser: RGB, per-pixel body ids and metric depth in one call.

One ``Renderer`` per process (pybullet DIRECT clients are per process). ``reset()`` empties
the world between tasks, so what a task renders never depends on what the process rendered
before it: that is what keeps the bytes identical whatever the number of workers.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass

import cv2
import numpy as np
import pybullet as p

from pin_match.data.synth.placing import FRONT_AZIMUTH
from pin_match.data.synth.shapes import Mesh

NEAR, FAR = 0.03, 30.0


@dataclass(frozen=True)
class Light:
    """TinyRenderer's single directional light (the direction points from the scene towards the light)."""

    direction: tuple[float, float, float] = (0.4, -0.6, 1.0)
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ambient: float = 0.55
    diffuse: float = 0.5
    specular: float = 0.1


@dataclass(frozen=True)
class Camera:
    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)


def vertical_fov(hfov_deg: float, width: int, height: int) -> float:
    """pybullet wants the vertical field of view; PIN specifies the horizontal one."""
    return float(np.degrees(2 * np.arctan(np.tan(np.radians(hfov_deg) / 2) * height / width)))


class Renderer:
    """A DIRECT pybullet client with helpers to add textured meshes and take pictures."""

    def __init__(self) -> None:
        self.client = p.connect(p.DIRECT)
        self._folder = tempfile.TemporaryDirectory(prefix="pin_match_synth_")  # removed on close, or at exit
        self._textures = 0

    def reset(self) -> None:
        p.resetSimulation(physicsClientId=self.client)

    def texture(self, image: np.ndarray) -> int:
        """Load an RGB uint8 texture (pybullet only reads textures from files, so go through a temporary PNG).

        Each texture gets a new file name: pybullet caches textures by name, even across resets.
        """
        self._textures += 1
        path = os.path.join(self._folder.name, f"texture{self._textures}.png")
        cv2.imwrite(path, cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR))
        try:
            tex = p.loadTexture(path, physicsClientId=self.client)
        finally:
            os.remove(path)
        if tex < 0:
            raise RuntimeError(f"pybullet could not load a {image.shape} texture")
        return tex

    def add(self, mesh: Mesh, texture: np.ndarray, position=(0.0, 0.0, 0.0), yaw: float = 0.0) -> int:
        """Add a static textured mesh; returns its body id (what the segmentation buffer reports)."""
        uvs = np.stack([mesh.uvs[:, 0], 1.0 - mesh.uvs[:, 1]], 1)  # TinyRenderer reads v from the image bottom
        shape = p.createVisualShape(p.GEOM_MESH, vertices=mesh.vertices.tolist(), indices=mesh.faces.ravel().tolist(),
                                    uvs=uvs.tolist(), normals=mesh.normals().tolist(), physicsClientId=self.client)
        if shape < 0:
            raise RuntimeError(f"pybullet rejected a mesh of {len(mesh.vertices)} vertices")
        body = p.createMultiBody(0, -1, shape, basePosition=list(position),
                                 baseOrientation=p.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=self.client)
        p.changeVisualShape(body, -1, textureUniqueId=self.texture(texture), rgbaColor=[1, 1, 1, 1],
                            physicsClientId=self.client)
        return body

    def render(self, camera: Camera, width: int, height: int, vfov_deg: float, light: Light,
               shadow: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """RGB (H x W x 3 uint8), body ids (H x W int32, -1 where nothing) and depth along the view axis (m)."""
        view = p.computeViewMatrix(camera.eye, camera.target, camera.up, physicsClientId=self.client)
        proj = p.computeProjectionMatrixFOV(vfov_deg, width / height, NEAR, FAR, physicsClientId=self.client)
        _, _, rgba, zbuf, seg = p.getCameraImage(
            width, height, view, proj, renderer=p.ER_TINY_RENDERER,
            flags=p.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX, shadow=int(shadow),
            lightDirection=list(light.direction), lightColor=list(light.colour),
            lightAmbientCoeff=light.ambient, lightDiffuseCoeff=light.diffuse, lightSpecularCoeff=light.specular,
            physicsClientId=self.client)
        rgb = np.asarray(rgba, np.uint8).reshape(height, width, 4)[..., :3].copy()
        seg = np.asarray(seg, np.int64).reshape(height, width)
        ids = np.where(seg < 0, -1, seg & ((1 << 24) - 1)).astype(np.int32)
        z = np.asarray(zbuf, np.float64).reshape(height, width)
        depth = (FAR * NEAR / (FAR - (FAR - NEAR) * z)).astype(np.float32)
        depth[ids < 0] = 0.0
        return rgb, ids, depth

    def close(self) -> None:
        p.disconnect(self.client)
        self._folder.cleanup()


# ------------------------------------------------------------------ reference views
REFERENCE_SIZE = (360, 480)  # H x W; PIN's are 960 x 1280, the same 3:4
REFERENCE_LIGHT = Light(direction=(-0.5, -1.0, 1.6), ambient=0.6, diffuse=0.5, specular=0.15)
SUPERSAMPLE = 1.5  # 2.25 samples per pixel: soft alpha edges at about half the cost of 2 x 2


def reference_views(renderer: Renderer, mesh: Mesh, atlas: np.ndarray,
                    size: tuple[int, int] = REFERENCE_SIZE) -> list[np.ndarray]:
    """PIN's three views: frontal after a 30 degree yaw (the side ``FRONT_AZIMUTH``, which placement turns to the
    room), the back, and from above, RGBA on transparent.

    Rendered at 1.5 times the size and area-averaged down, so alpha is the true pixel coverage
    (soft edges), not a jagged 0/255 cut-out; colours are not premultiplied and RGB outside the
    object is white.
    """
    renderer.reset()
    body = renderer.add(mesh, atlas)
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2)
    h, w = int(size[0] * SUPERSAMPLE), int(size[1] * SUPERSAMPLE)
    vfov = 40.0
    dist = radius / np.sin(np.radians(vfov / 2)) * 1.05
    elev = np.radians(20)
    views = []
    for azimuth, above in ((FRONT_AZIMUTH, False), (FRONT_AZIMUTH + np.pi, False), (0.0, True)):
        if above:
            cam = Camera(tuple(centre + [0, 0, dist]), tuple(centre), (0.0, 1.0, 0.0))
        else:
            d = np.array([np.cos(azimuth) * np.cos(elev), np.sin(azimuth) * np.cos(elev), np.sin(elev)])
            cam = Camera(tuple(centre + dist * d), tuple(centre))
        rgb, ids, _ = renderer.render(cam, w, h, vfov, REFERENCE_LIGHT)
        cover = (ids == body).astype(np.float32)
        small = cv2.resize(np.dstack([rgb.astype(np.float32) * cover[..., None], cover]), (size[1], size[0]),
                           interpolation=cv2.INTER_AREA)
        alpha = small[..., 3:]
        colour = np.where(alpha > 0, small[..., :3] / np.maximum(alpha, 1e-6), 255.0)
        views.append(np.clip(np.round(np.dstack([colour, alpha * 255.0])), 0, 255).astype(np.uint8))
    return views
