"""How much a synthetic set holds, apart from the generator so the command line reads it without loading pybullet."""

from __future__ import annotations

from dataclasses import dataclass

from pin_match.data.agent import MAX_STEPS


@dataclass(frozen=True)
class SynthSize:
    """How much a synthetic set holds; the seed draws everything else. The defaults are the embedded default set:
    15 episodes per split, so each shipped family with a target and a look-alike in a split is a target once
    there (15 of the 17 in each: the file sorter and the mug have no train instance, the portable drive and the
    shoes no val one)."""

    seed: int = 0
    episodes: int = 30
    objects_per_family: int = 5
    frames_per_episode: int = MAX_STEPS  # the tour's step budget: PIN's episode limit (it ends sooner, when done)
    splits: tuple[str, ...] = ("train", "val")  # the splits rendered (the others planned alike, left out)
    walk: str = "explore"  # "explore": blind to the target, one per house; "seek": heads for the target
    rooms: int = 3  # rooms per house, in a row joined by doors


DEFINITION_READS = ("data/agent.py", "data/compose.py", "data/geometry.py", "data/synth/__init__.py",
                    "data/synth/clutter.py", "data/synth/generator.py", "data/synth/house.py", "data/synth/objects.py",
                    "data/synth/placing.py", "data/synth/render.py", "data/synth/scans.py", "data/synth/scene.py",
                    "data/synth/sensor.py", "data/synth/shapes.py", "data/synth/size.py", "data/synth/textures.py",
                    "data/synth/tour.py", "data/synth/walk.py")  # the code a house is made by, under the package:
# with the scans, what ``generate.definition`` hashes; every module of ``synth`` but ``walkups``, which keeps views

GENERATOR = "pin_match.data.synth"  # the provenance's ``generator`` of a set this package's generator wrote


def made_by_generator(manifest: dict) -> bool:
    """Was the set written by the synthetic generator (its houses can be staged again, if this install made it)?"""
    return (manifest.get("provenance") or {}).get("generator") == GENERATOR


WALKS = ("explore", "seek")  # an exploration blind to the target, one a house; a walk that seeks the target out
DEFAULT_SIZE = SynthSize()  # the embedded default set
# named sizes: ``pin-match synth --preset NAME``. "bench": 100 val episodes, so SR, SPL and CE rank matchers with
# intervals of about +-10 points (15 episodes move SR in steps of 6.7 points, its interval spanning about +-25)
PRESETS = {"default": DEFAULT_SIZE, "bench": SynthSize(episodes=200)}
