"""Turn what a PIN user records in Habitat into a frame-set.

A recording folder holds, per episode, the RGB frames, the semantic frames with PIN's
labels (100000 target, 100001 same-category distractor, 100002 other distractor) and
optionally depth, next to the PInNED episodes JSON and a PInNED objects folder. PIN's
semantic sensor gives one label per role, not per instance, so distractor rows in the
visibility table carry the role with an empty object id.

Layout::

    recording/episodes.json[.gz]        PInNED episodes (episode_id, goals[0], distractors[])
    recording/<episode_id>/rgb/<step>.png|.jpg
    recording/<episode_id>/semantic/<step>.npy     int, PIN labels
    recording/<episode_id>/depth/<step>.npy        float metres (optional)
    objects/objects_images/<object_id>/*.png, objects/objects_descriptions.json
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

from pin_match.frameset import DESCRIPTIONS, OBJECT_IMAGES, FrameSet, FrameSetError, read_image, view_files
from pin_match.frameset_writer import FrameSetWriter

TARGET_ID, SAME_CATEGORY_ID, OTHER_ID = 100000, 100001, 100002
# PIN label -> (mask value, role) in the frame-set's instance mask
LABELS = {TARGET_ID: (1, "target"), SAME_CATEGORY_ID: (2, "same_category"), OTHER_ID: (3, "other")}


def _load_episodes(recording: Path) -> list[dict]:
    for name in ("episodes.json", "episodes.json.gz"):
        path = recording / name
        if path.exists():
            opener = gzip.open if name.endswith(".gz") else open
            with opener(path, "rt", encoding="utf-8") as fh:
                data = json.load(fh)
            episodes = data["episodes"] if isinstance(data, dict) else data
            if not isinstance(episodes, list):
                raise FrameSetError(f"{path}: expected a list of episodes")
            return episodes
    raise FrameSetError(f"missing file {recording / 'episodes.json'} (PInNED episodes)")


def _descriptions(objects: Path) -> dict[str, list[str]]:
    path = objects / DESCRIPTIONS
    if not path.exists():
        raise FrameSetError(f"missing file {path}")
    raw = json.loads(path.read_text(encoding="utf-8"))
    return {str(k): (v["descriptions"] if isinstance(v, dict) else v) for k, v in raw.items()}


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
                     name: str | None = None, overwrite: bool = False) -> FrameSet:
    """Build a frame-set at ``out`` from a recording folder and a PInNED objects folder."""
    recording, objects = Path(recording), Path(objects)
    episodes = _load_episodes(recording)
    descriptions = _descriptions(objects)
    writer = FrameSetWriter(out, name or recording.name, overwrite=overwrite,
                            provenance=dict(importer="pin_match.importer", recording=str(recording)))
    with writer:
        categories: dict[str, str] = {}
        for ep in episodes:
            for goal in [ep["goals"][0], *ep.get("distractors", [])]:
                categories[str(goal["object_id"])] = str(goal["object_category"])
        for object_id, category in categories.items():
            folder = objects / OBJECT_IMAGES / object_id
            if not folder.is_dir():
                raise FrameSetError(f"object {object_id!r}: missing reference folder {folder}")
            if object_id not in descriptions:
                raise FrameSetError(f"object {object_id!r}: no entry in {objects / DESCRIPTIONS}")
            views = [read_image(p, rgba=True) for p in view_files(folder)]
            writer.add_object(object_id, category, split, views, descriptions[object_id])
        for ep in episodes:
            episode_id = str(ep["episode_id"])
            target = str(ep["goals"][0]["object_id"])
            writer.add_episode(episode_id, str(ep.get("split", split)), str(ep.get("scene_id", "")), target,
                               [str(d["object_id"]) for d in ep.get("distractors", [])])
            _import_episode(writer, recording / episode_id, episode_id, target)
        return writer.close()


def _import_episode(writer: FrameSetWriter, folder: Path, episode_id: str, target: str) -> None:
    rgb = _frame_files(folder / "rgb", (".png", ".jpg", ".jpeg"))
    if not rgb:
        raise FrameSetError(f"episode {episode_id!r}: no RGB frames in {folder / 'rgb'}")
    semantic = _frame_files(folder / "semantic", (".npy",))
    depth = _frame_files(folder / "depth", (".npy",))
    legend = {1: (target, "target"), 2: (None, "same_category"), 3: (None, "other")}
    for step in sorted(rgb):
        if step not in semantic:
            raise FrameSetError(f"episode {episode_id!r}: frame {rgb[step]} has no semantic frame "
                                f"{folder / 'semantic' / f'{step}.npy'}")
        image = read_image(rgb[step])
        labels = np.load(semantic[step], allow_pickle=False)
        if labels.shape[:2] != image.shape[:2]:
            raise FrameSetError(f"{semantic[step]}: shape {labels.shape} differs from {rgb[step]} {image.shape[:2]}")
        mask = np.zeros(labels.shape[:2], np.uint16)
        for label, (value, _) in LABELS.items():
            mask[labels.reshape(mask.shape) == label] = value
        d = np.load(depth[step], allow_pickle=False).reshape(mask.shape).astype(np.float32) if step in depth else None
        writer.add_frame(episode_id, step, image, mask, legend, d)
