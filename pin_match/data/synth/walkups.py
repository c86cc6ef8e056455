"""Walk-ups rendered on demand: a synthetic set's houses staged again, and what an agent saw walking up, as frames.

A walk that fires on a candidate sends the agent toward it (``data.walkup``); what it sees on the way depends on
where the candidate was, so it cannot be rendered when the set is written. ``SynthHouses`` stages a set's houses
again from its provenance, the same houses bit for bit, and refuses a set this install would stage differently
(another generator version, changed scans or rendering code: the set's ``definition``). Each view is rendered once
and kept by its pose (``pose_key``) in a folder beside the scores; ``write_walkup_set`` writes the views asked for
as a frame-set of their own (``provenance.kind = "walk-ups"``), one episode per episode of the set that asked,
so the scoring engine scores them as it scores any frame (chunks, resume, cache by matcher and frame-set).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.data.synth.generator import GENERATOR_VERSION, definition, plan_set
from pin_match.data.synth.house import HousePlan, HouseWorld
from pin_match.data.synth.objects import SynthError
from pin_match.data.synth.scans import PACKAGED_SCANS, ScanFolder
from pin_match.data.synth.size import GENERATOR, SynthSize, made_by_generator
from pin_match.data.walkup import Pose, pose_key
from pin_match.data.writer import Frame, FrameSetWriter, ImageFile, ObjectOrigin, encode_frame, millimetres


class HouseError(SynthError):
    """A set whose houses this install cannot stage again exactly."""


class SynthHouses:
    """A synthetic set's houses as this install stages them; ``render`` a house's views, each once, kept by pose
    under ``cache``."""

    def __init__(self, fs: FrameSet, cache: Path) -> None:
        provenance = fs.manifest.get("provenance") or {}
        if not made_by_generator(fs.manifest):
            raise HouseError(f"{fs.root} was not written by pin_match's generator: it has no house to render a "
                             "walk-up in (its walk-ups are what was recorded, if anything)")
        scans = provenance.get("scans")
        folder = ScanFolder.open(PACKAGED_SCANS if scans == "packaged" else scans)
        here, built = definition(folder), provenance.get("definition")
        if built != here:
            raise HouseError(f"{fs.root} was built by generator {provenance.get('version')} with set definition "
                             f"{built}; this install (generator {GENERATOR_VERSION}) stages definition {here}: its "
                             "houses would differ, so no walk-up is rendered (rebuild the set with this install)")
        size = SynthSize(seed=int(provenance["seed"]), episodes=int(provenance["episodes"]),
                         objects_per_family=int(provenance["objects_per_family"]),
                         frames_per_episode=int(provenance["frames_per_episode"]), walk=str(provenance["walk"]),
                         rooms=int(provenance["rooms"]))
        self.fs = fs
        self.plans: dict[str, HousePlan] = {plan.house_id: plan for plan in plan_set(size, folder)[1]}
        self.cache = cache
        self._world: HouseWorld | None = None

    def plan_of(self, episode_id: str) -> tuple[HousePlan, int]:
        """The plan of an episode's house and its target's index there."""
        house_id = str(self.fs.episode(episode_id)["scene_id"])
        plan = self.plans[house_id]
        return plan, dict(plan.episodes)[episode_id]

    def render(self, house_id: str, poses: Sequence[Pose]) -> dict[str, tuple[Frame, ImageFile]]:
        """Each view by its ``pose_key``: read where rendered before, else rendered in the staged house (staged once
        per run of houses) and kept. The frames' legends are empty: each episode gives its own."""
        out = {}
        for pose in poses:
            key = pose_key(pose)
            folder = self.cache / house_id
            if not (folder / f"{key}.npz").exists():
                if self._world is None or self._world.plan.house_id != house_id:
                    self._world = HouseWorld.build(self.plans[house_id])
                frame, stored = self._world.shot(pose, ("walk-up", key))
                atomic.write_bytes(folder / f"{key}.jpg", stored.data)  # type: ignore[arg-type]  # a shot's JPEG
                buffer = _npz(mask=frame.mask.astype(np.uint16), depth_mm=millimetres(frame.depth))
                atomic.write_bytes(folder / f"{key}.npz", buffer)
            out[key] = _read(folder, key)
        return out


def _npz(**arrays: np.ndarray) -> bytes:
    import io

    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def _read(folder: Path, key: str) -> tuple[Frame, ImageFile]:
    data = (folder / f"{key}.jpg").read_bytes()
    image = cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    with np.load(folder / f"{key}.npz") as stored:
        return Frame(image, stored["mask"], {}, stored["depth_mm"].astype(np.float32) / 1000.0), ImageFile(".jpg", data)


def request_name(fs: FrameSet, requests: Mapping[str, Sequence[Pose]]) -> str:
    """The name of the walk-up set of these requests (episode -> views): the same requests, the same set."""
    text = json.dumps({e: sorted(pose_key(p) for p in poses) for e, poses in sorted(requests.items())})
    return hashlib.sha256(f"{fs.fingerprint}/{text}".encode()).hexdigest()[:16]


def write_walkup_set(houses: SynthHouses, requests: Mapping[str, Sequence[Pose]], out: Path) -> FrameSet:
    """The views each episode asked for (episode -> views) as a frame-set at ``out``: its frames in ``pose_key``
    order, each with the episode's legend, its objects those of the episodes. Read back where it exists."""
    if (out / "frameset.json").exists():
        return FrameSet.load(out)
    fs = houses.fs
    writer = FrameSetWriter(out, out.name, overwrite=True,
                            provenance=dict(kind="walk-ups", of=fs.fingerprint, generator=GENERATOR))
    with writer:
        episodes = fs.episodes.set_index("episode_id")
        wanted = sorted({o for e in requests for o in [episodes.loc[e, "target_object_id"],
                                                        *episodes.loc[e, "distractor_object_ids"]]})
        objects = fs.objects.set_index("object_id")
        for object_id in wanted:
            target = fs.target(object_id)
            row = objects.loc[object_id]
            writer.add_object(object_id, target.category, str(row["split"]), list(target.views),
                              list(target.descriptions),
                              origin=ObjectOrigin(str(row.get("source", "") or ""), str(row.get("licence", "") or "")))
        for episode_id in sorted(requests):
            record = episodes.loc[episode_id]
            writer.add_episode(episode_id, str(record["split"]), str(record["scene_id"]),
                               str(record["target_object_id"]), list(record["distractor_object_ids"]))
            plan, target = houses.plan_of(episode_id)
            shots = houses.render(plan.house_id, requests[episode_id])
            for step, key in enumerate(sorted(shots)):
                frame, stored = shots[key]
                writer.add_frame_record(encode_frame(writer.staging, episode_id, step,
                                                     replace(frame, legend=plan.legend(target)), stored))
        return writer.close()
