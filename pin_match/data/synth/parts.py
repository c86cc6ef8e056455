"""The assembly kit every category builder uses: meshes with their texture tiles, packed into one atlas.

A builder in ``builders.py`` adds parts (a mesh and the tile it is textured with) to a
``Parts``; ``assemble`` packs the tiles into a square atlas, remaps each mesh's UVs into its
tile and stands the merged mesh on z = 0, centred, so every category comes out the same way.
"""

from __future__ import annotations

import numpy as np

from pin_match.data.synth import prints
from pin_match.data.synth import textures as tx
from pin_match.data.synth.objects import Look
from pin_match.data.synth.shapes import Mesh, lathe, merge, split_facing

FRONT, UP = (0, -1, 0), (0, 0, 1)


class Parts:
    """Collects (mesh, texture tile) pairs of one object and packs the tiles into an atlas."""

    def __init__(self, look: Look, rng: np.random.Generator, spread: float) -> None:
        self.look, self.rng, self.spread = look, rng, spread
        self.meshes: list[tuple[Mesh, int]] = []
        self.tiles: list[np.ndarray] = []
        self.c1 = tx.rgb(look.colour, rng, 0.04)
        self.c2 = tx.rgb(look.colour2, rng, 0.04)

    def j(self, value: float, amount: float = 1.0) -> float:
        """A proportion, jittered by the instance's scale and the category's spread."""
        return value * self.look.scale * float(np.exp(self.rng.normal(0, 0.08 * self.spread * amount)))

    def tile(self, img: np.ndarray) -> int:
        self.tiles.append(img)
        return len(self.tiles) - 1

    def add(self, mesh: Mesh, tile: int) -> None:
        self.meshes.append((mesh, tile))

    def solid(self, colour: np.ndarray, grain: float = 6.0) -> int:
        return self.tile(tx.solid(colour, self.rng, grain))

    def body(self, front_u: float | None = 0.5, front_v: float = 0.45, logo: bool = True) -> int:
        """The main material: colour, pattern, and (when ``logo``) the photo print and printed word at the front."""
        lk = self.look
        if lk.colour == "tortoiseshell":
            img = tx.pattern("camouflage", self.c1, tx.rgb("tan"), self.rng, scale=2)
        else:
            img = tx.pattern(lk.pattern, self.c1, self.c2, self.rng)
        if logo and front_u is not None:
            narrow = front_u in (0.25, 0.75)  # a quarter of a surface of revolution: the front
            if lk.photo:
                tx.photo(img, prints.image(lk.photo), (front_u, front_v), 0.3 if narrow else 0.6)
            if lk.word:
                tx.text(img, lk.word, tx.contrasting(self.c1), (front_u, front_v), 0.28 if narrow else 0.7,
                        label=None if lk.pattern == "plain" else self.c1)
        return self.tile(img)

    def boxed(self, mesh: Mesh, front_tile: int, rest_tile: int, facing=FRONT) -> None:
        """A box whose front face carries the logo and whose other faces are plain."""
        front, rest = split_facing(mesh, facing)
        self.add(front, front_tile)
        self.add(rest, rest_tile)

    def assemble(self) -> tuple[Mesh, np.ndarray]:
        grid = int(np.ceil(np.sqrt(len(self.tiles))))
        size = tx.TILE
        atlas = np.zeros((grid * size, grid * size, 3), np.uint8)
        for k, img in enumerate(self.tiles):
            r, c = divmod(k, grid)
            atlas[r * size:(r + 1) * size, c * size:(c + 1) * size] = img
        mesh = merge([m.in_tile(t, grid) for m, t in self.meshes])
        lo, hi = mesh.bounds
        mesh = mesh.moved((-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]))
        return mesh, atlas


def flat_ring(r_in: float, r_out: float, thickness: float, segments: int = 32) -> Mesh:
    """A flat annulus with thickness (brims), as a closed profile of revolution."""
    return lathe([r_in, r_out, r_out, r_in, r_in], [0, 0, thickness, thickness, 0], segments, caps=False)
