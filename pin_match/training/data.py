"""The train split as the head sees it: crops from the feature store, queries per episode, held-out objects."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.training.config import TrainConfig, TrainingError
from pin_match.training.features import FeatureStore


@dataclass
class TrainData:
    """Index arrays into the store for the train split, and the query sets of its episodes."""

    store: FeatureStore
    crops: pd.DataFrame                  # train crops (store rows), with their episode
    queries: dict[str, list[int]]        # episode id -> object indices with references: target + siblings
    fit_objects: set[int]
    holdout_objects: set[int]
    visible: dict[str, set[int]]         # frame id -> object indices visible in it
    frame_episode: dict[str, str] = field(default_factory=dict)


def _split_objects(fs: FrameSet, train_objects: list[str], holdout: float, seed: int) -> tuple[list[str], list[str]]:
    """Per category, a seeded share of the train objects is held out (at least one where a category has two)."""
    cats = fs.objects.set_index("object_id").category
    fit, held = [], []
    for category in sorted({cats[o] for o in train_objects}):
        members = sorted(o for o in train_objects if cats[o] == category)
        order = np.random.default_rng([seed, sum(category.encode())]).permutation(len(members))
        n_held = min(len(members) - 1, max(1 if len(members) > 1 else 0, int(round(holdout * len(members)))))
        held += [members[i] for i in order[:n_held]]
        fit += [members[i] for i in order[n_held:]]
    return sorted(fit), sorted(held)


def check_trainable(fs: FrameSet) -> None:
    """A frame-set must have a train split that shows look-alikes; say what is missing before any model runs."""
    if "train" not in set(fs.episodes.split):
        raise TrainingError(f"frame-set {fs.root} has no train split (its episodes are in "
                            f"{sorted(set(fs.episodes.split))}); training needs train episodes with ground-truth "
                            f"masks, e.g. pin-match synth OUT")
    train = fs.split("train")
    if not (train.visibility.role == "same_category").any():
        raise TrainingError(f"the train split of {fs.root} shows no same-category distractor in any frame: "
                            f"nothing to learn look-alikes from (generate episodes with same-category distractors)")


def prepare_data(fs: FrameSet, store: FeatureStore, cfg: TrainConfig) -> TrainData:
    """The train split's crops and queries, after checking that it can teach anything about look-alikes."""
    check_trainable(fs)
    train = fs.split("train")
    index = store.object_index()
    cats = fs.objects.set_index("object_id").category
    queries: dict[str, list[int]] = {}
    for ep in train.episodes.itertuples(index=False):
        same_ids = [o for o in ep.distractor_object_ids if cats[o] == ep.target_category]
        queries[ep.episode_id] = [index[o] for o in [ep.target_object_id, *same_ids]]
    query_objects = sorted({store.objects[i] for q in queries.values() for i in q})
    fit, held = _split_objects(fs, query_objects, cfg.holdout, cfg.seed)
    crops = store.crops[store.crops.split == "train"].reset_index(drop=True)
    if crops.empty:
        raise TrainingError(f"feature store {store.path} holds no crop of the train split; build it for all splits "
                            f"or --split train")
    vis = train.visibility[train.visibility.object_id.isin(index)]
    visible = {fid: {index[o] for o in g.object_id} for fid, g in vis.groupby("frame_id")}
    return TrainData(store, crops, queries, {index[o] for o in fit}, {index[o] for o in held}, visible,
                     dict(zip(train.frames.frame_id, train.frames.episode_id)))


def epoch_batches(data: TrainData, cfg: TrainConfig, epoch: int) -> list[np.ndarray]:
    """Store crop indices per step: each episode's crops shuffled and cut, then the steps shuffled; seeded by epoch."""
    rng = np.random.default_rng([cfg.seed, epoch])
    batches = []
    for episode_id, group in data.crops.groupby("episode_id", sort=True):
        if not set(data.queries[episode_id]) & data.fit_objects:
            continue
        idx = group.crop_index.to_numpy()[rng.permutation(len(group))]
        batches += [np.sort(idx[i:i + cfg.batch_crops]) for i in range(0, len(idx), cfg.batch_crops)]
    order = rng.permutation(len(batches))
    return [batches[i] for i in order]
