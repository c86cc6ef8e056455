"""A PIN episode's fields as the recording's ``episodes.json`` stores them.

PIN's Habitat episode (``PINEpisodeV1``) holds ``goals`` as ``ObjectGoal`` objects and
``distractors`` as loaded from the episodes JSON, so every field is read from a mapping or
an attribute alike. Only what ``pin-match import`` reads is kept.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pin_match.data.frameset import SPLITS
from pin_match.data.importer import OTHER_ID, SAME_CATEGORY_ID, TARGET_ID
from pin_match.errors import PinMatchError

_MISSING = object()


class EpisodeFieldsError(PinMatchError, ValueError):
    """An episode without the PInNED fields the importer needs."""


def _get(obj: Any, name: str, default: Any = _MISSING) -> Any:
    value = obj.get(name, default) if isinstance(obj, Mapping) else getattr(obj, name, default)
    if value is _MISSING:
        raise EpisodeFieldsError(f"episode field {name!r} missing in {str(obj)[:120]}")
    return value


def _goal(obj: Any) -> dict[str, Any]:
    """A goal's or distractor's ids, and its ``position`` (Habitat's world frame) where the episode places it."""
    out: dict[str, Any] = dict(object_id=str(_get(obj, "object_id")), object_category=str(_get(obj, "object_category")))
    position = _get(obj, "position", None)
    if position is not None:
        out["position"] = _floats(position, 3, f"position of object {out['object_id']!r}")
    return out


def _floats(value: Any, n: int, what: str) -> list[float]:
    try:
        out = [float(v) for v in value]
    except (TypeError, ValueError):
        out = []
    if len(out) != n:
        raise EpisodeFieldsError(f"{what} must be {n} numbers, got {str(value)[:80]}")
    return out


def _geometry(episode: Any) -> dict[str, Any]:
    """PIN's start pose and geodesic length (``start_position``, ``start_rotation`` as Habitat's [x, y, z, w],
    ``info.geodesic_distance``) where the episode has them: what the importer needs to place the agent."""
    out: dict[str, Any] = {}
    start, rotation = _get(episode, "start_position", None), _get(episode, "start_rotation", None)
    if start is not None and rotation is not None:
        out["start_position"] = _floats(start, 3, "start_position")
        out["start_rotation"] = _floats(rotation, 4, "start_rotation")
    info = _get(episode, "info", None) or {}
    geodesic = info.get("geodesic_distance") if isinstance(info, Mapping) else getattr(info, "geodesic_distance", None)
    if geodesic is not None:
        out["info"] = {"geodesic_distance": float(geodesic)}
    return out


def episode_record(episode: Any, split: str | None = None) -> dict[str, Any]:
    """``{episode_id, scene_id, goals: [target], distractors: [...], split?}`` from a PInNED episode, with PIN's
    geometry fields (positions, start pose, geodesic length) where it has them."""
    episode_id = str(_get(episode, "episode_id"))
    if not episode_id or episode_id.startswith(".") or "/" in episode_id or "\\" in episode_id:
        raise EpisodeFieldsError(f"episode id {episode_id!r} cannot name a folder of the recording")
    goals = _get(episode, "goals")
    if not goals:
        raise EpisodeFieldsError(f"episode {episode_id!r} has no goals (PInNED: goals[0] is the target)")
    record = dict(episode_id=episode_id, scene_id=str(_get(episode, "scene_id", "")), goals=[_goal(goals[0])],
                  distractors=[_goal(d) for d in (_get(episode, "distractors", None) or [])], **_geometry(episode))
    if split is not None:
        if split not in SPLITS:
            raise EpisodeFieldsError(f"split {split!r} is not one of {SPLITS}")
        record["split"] = split
    return record


def labels_in_episode(record: dict[str, Any]) -> set[int]:
    """The PIN semantic labels an episode can show: the target's, and each distractor role it places."""
    category = record["goals"][0]["object_category"]
    labels = {TARGET_ID}
    for d in record["distractors"]:
        labels.add(SAME_CATEGORY_ID if d["object_category"] == category else OTHER_ID)
    return labels
