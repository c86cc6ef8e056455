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


def _goal(obj: Any) -> dict[str, str]:
    return dict(object_id=str(_get(obj, "object_id")), object_category=str(_get(obj, "object_category")))


def episode_record(episode: Any, split: str | None = None) -> dict[str, Any]:
    """``{episode_id, scene_id, goals: [target], distractors: [...], split?}`` from a PInNED episode."""
    episode_id = str(_get(episode, "episode_id"))
    if not episode_id or episode_id.startswith(".") or "/" in episode_id or "\\" in episode_id:
        raise EpisodeFieldsError(f"episode id {episode_id!r} cannot name a folder of the recording")
    goals = _get(episode, "goals")
    if not goals:
        raise EpisodeFieldsError(f"episode {episode_id!r} has no goals (PInNED: goals[0] is the target)")
    record = dict(episode_id=episode_id, scene_id=str(_get(episode, "scene_id", "")), goals=[_goal(goals[0])],
                  distractors=[_goal(d) for d in (_get(episode, "distractors", None) or [])])
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
