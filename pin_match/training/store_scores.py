"""Scores computed from the feature store, with or without a head: validation, sigma, and learned vs frozen.

With ``head=None`` every function here gives the frozen prototype matcher's numbers, from
the same stored tokens, so the comparison isolates what the head learned.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import torch

from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.metrics import auroc
from pin_match.nn.head import prototypes
from pin_match.nn.prototypes import patch_scores
from pin_match.training.config import TrainingError
from pin_match.training.data import TrainData
from pin_match.training.features import FeatureStore


@torch.inference_mode()
def store_crop_scores(store: FeatureStore, head: torch.nn.Module | None, crop_idx: np.ndarray,
                      objects: list[int], chunk: int = 64) -> np.ndarray:
    """(len(crop_idx), len(objects)) crop scores by the matcher's own rule (``patch_scores``), max over patches.

    With ``head=None`` this is the frozen prototype matcher's score, from the stored tokens.
    """
    head = head if head is not None else torch.nn.Identity()
    refs = torch.from_numpy(np.asarray(store.refs[objects], np.float32))
    alpha = torch.from_numpy(np.asarray(store.ref_alpha[objects], np.float32))
    protos = prototypes(head, refs, alpha)
    out = np.empty((len(crop_idx), len(objects)), np.float32)
    for start in range(0, len(crop_idx), chunk):
        idx = crop_idx[start:start + chunk]
        tokens = head(torch.from_numpy(np.asarray(store.frames[idx], np.float32)))
        out[start:start + len(idx)] = patch_scores(tokens, protos).amax(1).numpy()
    return out


def store_frame_scores(store: FeatureStore, fs: FrameSet, head: torch.nn.Module | None = None,
                       split: str | None = None) -> pd.DataFrame:
    """Each frame's score for its episode's target (max over crops), as the matcher would give: frame_id, score."""
    crops = store.crops if split in (None, "all") else store.crops[store.crops.split == split]
    index = store.object_index()
    target = dict(zip(fs.episodes.episode_id, fs.episodes.target_object_id))
    rows = []
    for episode_id, group in crops.groupby("episode_id", sort=True):
        s = store_crop_scores(store, head, group.crop_index.to_numpy(), [index[target[episode_id]]])[:, 0]
        per_frame = pd.Series(s, index=group.frame_id.to_numpy()).groupby(level=0, sort=False).max()
        rows.append(pd.DataFrame({"frame_id": per_frame.index, "score": per_frame.to_numpy(np.float64)}))
    return pd.concat(rows, ignore_index=True) if rows else pd.DataFrame(columns=["frame_id", "score"])


def query_frames(data: TrainData, head: torch.nn.Module | None, objects: set[int],
                 relevant_only: bool = False) -> pd.DataFrame:
    """Scored frames in the metrics' layout, one pseudo-episode per (train episode, query object in ``objects``).

    The query plays the target: frames showing it are TM, frames showing a sibling but not
    it CM, other visible objects GM. This is how held-out objects give a validation AUROC
    and a sigma with the same objective as ``pin-match tune``. ``relevant_only`` keeps only
    frames showing one of the episode's queries, all the AUROC needs (about a third of the cost).
    """
    store = data.store
    cats = {i: c for i, c in enumerate(store.meta.get("categories", []))}
    rows = []
    for episode_id, group in data.crops.groupby("episode_id", sort=True):
        query = [u for u in data.queries[episode_id] if u in objects]
        if not query:
            continue
        if relevant_only:
            shown = set(data.queries[episode_id])
            group = group[[bool(data.visible.get(f, set()) & shown) for f in group.frame_id]]
            if group.empty:
                continue
        scores = store_crop_scores(store, head, group.crop_index.to_numpy(), query)
        frame = pd.DataFrame(scores, columns=query)
        frame["frame_id"] = group.frame_id.to_numpy()
        frame["step"] = group.step.to_numpy()
        per_frame = frame.groupby(["frame_id", "step"], sort=False).max().reset_index()
        siblings = set(data.queries[episode_id])
        for u in query:
            vis = [data.visible.get(f, set()) for f in per_frame.frame_id]
            rows.append(pd.DataFrame(dict(
                frame_id=per_frame.frame_id, episode_id=f"{episode_id}:{store.objects[u]}", step=per_frame.step,
                target_category=cats.get(u, ""), target_visible=[u in v for v in vis],
                same_visible=[bool(v & (siblings - {u})) for v in vis],
                other_visible=[bool(v - siblings) for v in vis], target_seen=np.nan,
                score=per_frame[u].to_numpy(np.float64))))
    return pd.concat(rows, ignore_index=True)


def validation_auroc(scored: pd.DataFrame) -> float:
    """AUROC of frames showing the query vs frames showing only a look-alike of it (the metrics' auroc_same)."""
    return auroc(scored.score[scored.target_visible].to_numpy(),
                 scored.score[~scored.target_visible & scored.same_visible].to_numpy())


def scored_from_store(data: FrameSet | EvalContext, store: FeatureStore, head: torch.nn.Module | None,
                      name: str) -> pd.DataFrame:
    """Frame labels with the store-based score of every stored frame (the metrics' input), as scoring would give.

    ``data``'s labels are those of an ``EvalContext`` (built once however many scores are read against them).
    """
    from pin_match.scoring.table import ScoreTable

    ctx = EvalContext.of(data)
    scores = store_frame_scores(store, ctx.fs, head)
    return ctx.scored(ScoreTable(scores, dict(matcher=name, matcher_id=name,
                                              frameset_fingerprint=ctx.fs.fingerprint)), None)


def sigma_on_split(scored: pd.DataFrame, objective: str = "first-match", split: str = "train") -> float:
    """Sigma chosen on one split of scored frames, as ``pin-match tune`` chooses it."""
    from pin_match.evaluation.core.tuning import sigma_for

    part = scored[scored.split == split]
    if part.empty:
        raise TrainingError(f"no scored frames of split {split!r} to tune sigma on")
    return sigma_for(part, objective)


def compare_with_frozen(fs: FrameSet, store: FeatureStore, head: torch.nn.Module, sigmas: dict[str, float],
                        split: str = "val") -> dict:
    """Learned head vs the frozen prototype matcher of the same store on one split, at given sigmas.

    Returns per matcher ("frozen", "learned"): the scored frames of the split, the detection
    metrics at its sigma (AUROC target vs same-category is ``auroc_same``) and the
    per-category table.
    """
    from pin_match.evaluation.core.metrics import detection_metrics, frame_arrays, per_category

    ctx = EvalContext(fs)  # the labels once for both matchers
    out: dict[str, dict] = {}
    for name, h in (("frozen", None), ("learned", head)):
        scored = scored_from_store(ctx, store, h, name)
        scored = scored[scored.split == split].reset_index(drop=True)
        if scored.empty:
            raise TrainingError(f"feature store {store.root} holds no frame of split {split!r}")
        arr = frame_arrays(scored)  # once for both tables
        out[name] = dict(scored=scored, sigma=sigmas[name], metrics=detection_metrics(arr, sigmas[name]),
                         per_category=per_category(arr, sigmas[name]))
    return out
