"""Turn what a PIN user records in Habitat into a frame-set.

A recording folder holds, per episode, the RGB frames, the semantic frames with PIN's
labels (100000 target, 100001 same-category distractor, 100002 other distractor) and
optionally depth, next to the PInNED episodes JSON; a PInNED objects folder holds the
references. PIN's semantic sensor gives one label per role, not per instance, so
distractor rows in the visibility table carry the role with an empty object id.

Layout (docs/frameset.md, "Recordings from PIN")::

    recording/episodes.json[.gz]        PInNED episodes (episode_id, goals[0], distractors[], optional split)
    recording/<episode_id>/rgb/<step>.png|.jpg
    recording/<episode_id>/semantic/<step>.npy     int, PIN labels
    recording/<episode_id>/depth/<step>.npy        float metres (optional)
    objects/objects_images/<object_id>/<object_id>_<k>.png   k = 0 frontal, 1 back, 2 top; every goal AND distractor
    objects/objects_descriptions.json              {object_id: [3 descriptions]}, the same objects

Frames keep their source bytes by default (lossless: a PNG stays PNG, a JPEG is not
re-compressed); ``image_format="png"`` or ``"jpeg"`` re-encode.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pin_match import atomic
from pin_match.data.frameset import (
    DESCRIPTIONS,
    IMAGE_SUFFIXES,
    N_VIEWS,
    OBJECT_IMAGES,
    SPLITS,
    FrameSet,
    FrameSetError,
)
from pin_match.data.images import read_image
from pin_match.data.writer import FrameSetWriter, ImageFile

TARGET_ID, SAME_CATEGORY_ID, OTHER_ID = 100000, 100001, 100002
# PIN label -> (mask value, role) in the frame-set's instance mask
LABELS = {TARGET_ID: (1, "target"), SAME_CATEGORY_ID: (2, "same_category"), OTHER_ID: (3, "other")}
IMAGE_FORMATS = ("source", "png", "jpeg")
JPEG_SUFFIXES = (".jpg", ".jpeg")


def _load_episodes(recording: Path) -> list[dict]:
    for name in ("episodes.json", "episodes.json.gz"):
        path = recording / name
        if path.exists():
            data = atomic.read_json(path, FrameSetError, "PInNED episodes file")
            episodes = data.get("episodes") if isinstance(data, dict) else data
            if not isinstance(episodes, list):
                raise FrameSetError(f"{path}: expected a list of episodes (or {{'episodes': [...]}})")
            return episodes
    raise FrameSetError(f"missing file {recording / 'episodes.json'} (PInNED episodes)")


def _descriptions(objects: Path) -> dict[str, list[str]]:
    path = objects / DESCRIPTIONS
    raw = atomic.read_json(path, FrameSetError)  # a missing one: "missing file PATH"
    if not isinstance(raw, dict):
        raise FrameSetError(f"{path}: expected {{object_id: [3 descriptions]}}")
    out = {}
    for k, v in raw.items():
        texts = v.get("descriptions") if isinstance(v, dict) else v
        if not isinstance(texts, list) or not all(isinstance(t, str) and t.strip() for t in texts):
            raise FrameSetError(f"{path}: object {k!r} needs a list of 3 non-empty descriptions, got {str(v)[:80]}")
        out[str(k)] = texts
    return out


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
                     name: str | None = None, image_format: str = "source", overwrite: bool = False) -> FrameSet:
    """Build a frame-set at ``out`` from a recording folder and a PInNED objects folder.

    ``split`` is the split of episodes without a ``split`` key; every object takes the split of
    the episodes that use it. ``image_format``: "source" (keep each file's bytes), "png" or "jpeg".
    """
    recording, objects = Path(recording), Path(objects)
    if image_format not in IMAGE_FORMATS:
        raise FrameSetError(f"image format {image_format!r} is not one of {IMAGE_FORMATS}")
    episodes = _load_episodes(recording)
    descriptions = _descriptions(objects)
    categories, splits = _objects_of(episodes, split, recording)
    writer = FrameSetWriter(out, name or recording.name, overwrite=overwrite,
                            provenance=dict(importer="pin_match.data.importer", recording=str(recording),
                                            image_format=image_format))
    with writer:
        for object_id, category in categories.items():
            if object_id not in descriptions:
                raise FrameSetError(f"object {object_id!r}: no entry in {objects / DESCRIPTIONS} (every goal and "
                                    "distractor needs 3 descriptions)")
            views = [read_image(p, rgba=True) for p in reference_files(objects / OBJECT_IMAGES / object_id, object_id)]
            writer.add_object(object_id, category, splits[object_id], views, descriptions[object_id])
        for ep in episodes:
            episode_id = str(ep["episode_id"])
            target = str(ep["goals"][0]["object_id"])
            writer.add_episode(episode_id, _split(ep, split), str(ep.get("scene_id", "")), target,
                               [str(d["object_id"]) for d in ep.get("distractors", [])])
            _import_episode(writer, recording / episode_id, episode_id, target, image_format)
        return writer.close()


def _split(ep: dict, default: str) -> str:
    value = str(ep.get("split", default))
    if value not in SPLITS:
        raise FrameSetError(f"episode {ep.get('episode_id')!r}: split {value!r} is not one of {SPLITS}")
    return value


def _objects_of(episodes: list[dict], default_split: str, recording: Path) -> tuple[dict[str, str], dict[str, str]]:
    """Category and split of every object an episode names (goal or distractor), in first-use order."""
    categories: dict[str, str] = {}
    splits: dict[str, str] = {}
    for ep in episodes:
        if not isinstance(ep, dict) or "episode_id" not in ep or not ep.get("goals"):
            raise FrameSetError(f"{recording}: every episode needs an episode_id and goals, got {str(ep)[:80]}")
        ep_split = _split(ep, default_split)
        for goal in [ep["goals"][0], *ep.get("distractors", [])]:
            if not isinstance(goal, dict) or "object_id" not in goal or "object_category" not in goal:
                raise FrameSetError(f"episode {ep['episode_id']!r}: goal or distractor without object_id and "
                                    f"object_category: {str(goal)[:80]}")
            oid = str(goal["object_id"])
            categories.setdefault(oid, str(goal["object_category"]))
            if splits.setdefault(oid, ep_split) != ep_split:
                raise FrameSetError(f"object {oid!r} is used by {splits[oid]} and {ep_split} episodes: an object "
                                    "belongs to one split")
    return categories, splits


def reference_files(folder: Path, object_id: str) -> list[Path]:
    """``<id>_0`` (frontal), ``<id>_1`` (back), ``<id>_2`` (top): the order is the names', never a sort guess."""
    if not folder.is_dir():
        raise FrameSetError(f"object {object_id!r}: missing reference folder {folder} (every goal and distractor "
                            "needs one)")
    out = []
    for k in range(N_VIEWS):
        found = [f for f in (folder / f"{object_id}_{k}{ext}" for ext in IMAGE_SUFFIXES) if f.is_file()]
        if len(found) != 1:
            present = sorted(p.name for p in folder.iterdir())
            raise FrameSetError(f"object {object_id!r}: needs exactly one {object_id}_{k}.png (view {k}: 0 frontal, "
                                f"1 back, 2 top) in {folder}, found {present}")
        out.append(found[0])
    return out


def _import_episode(writer: FrameSetWriter, folder: Path, episode_id: str, target: str, image_format: str) -> None:
    rgb = _frame_files(folder / "rgb", IMAGE_SUFFIXES)
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
        labels = _load_array(semantic[step])
        if labels.shape[:2] != image.shape[:2] or labels.size != image.shape[0] * image.shape[1] \
                or not np.issubdtype(labels.dtype, np.integer):
            raise FrameSetError(f"{semantic[step]}: must be integer labels of shape {image.shape[:2]}, got "
                                f"{labels.dtype} {labels.shape}")
        mask = np.zeros(labels.shape[:2], np.uint16)
        for label, (value, _) in LABELS.items():
            mask[labels.reshape(mask.shape) == label] = value
        d = None
        if step in depth:
            d = _load_array(depth[step])
            if d.size != mask.size or not np.issubdtype(d.dtype, np.number):
                raise FrameSetError(f"{depth[step]}: must be depth in metres of shape {mask.shape}, got "
                                    f"{d.dtype} {d.shape}")
            d = d.reshape(mask.shape).astype(np.float32)
        writer.add_frame(episode_id, step, image, mask, legend, d, file=_stored_image(rgb[step], image_format))


def _stored_image(path: Path, image_format: str) -> ImageFile:
    """How one source frame is stored: re-encoded as PNG or JPEG, or (``source``) its own bytes as they are."""
    if image_format == "png":
        return ImageFile(".png")
    if image_format == "jpeg":
        return ImageFile(".jpg")
    return ImageFile(".jpg" if path.suffix.lower() in JPEG_SUFFIXES else ".png", path.read_bytes())


def _load_array(path: Path) -> np.ndarray:
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise FrameSetError(f"cannot read array {path}: {exc}") from exc
