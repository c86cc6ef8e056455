"""``pin-match train``: learn a projection head on the train split that tells the user's instance from look-alikes.

Data. Every object of a train episode that has references (the target and its
same-category distractors) serves as a query: its prototypes are compared with every
patch of every crop of that episode. For a query, a patch mostly covered by it is a
positive, a patch on a same-category sibling a hard negative (PIN's failure mode), any
other patch a negative. Part of the train objects of every category is held out: their
pixels never enter the loss, and the held-out queries give the validation AUROC (early
stopping) and the sigma, both on objects the head never learned from.

Loss (both terms on ``scale x (cosine - bias)`` with a learned scale and bias):
- a class-balanced BCE on patches: the mean over positives, over hard negatives and over
  the other negatives weigh the same, so the few sibling patches are not drowned by the
  background;
- a BCE on the crop's max-cosine against "the query is visible in the crop", balanced the
  same way over crops showing the query, crops showing only a sibling, and the rest: the
  matcher decides on the max over patches, so this term trains exactly the number that is
  thresholded, with the look-alike crops as a class of their own.

Determinism: features come from the store, the head's init from ``seed``, each epoch's
batch order from (seed, epoch); deterministic torch algorithms and a fixed thread count
make a run, and a run resumed after a kill, identical to the bit on the CPU.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch
import torch.nn.functional as F

from pin_match import atomic
from pin_match.features import DEFAULT_OUT, FeatureStore, build_features, patch_matcher, store_dir
from pin_match.frameset import FrameSet
from pin_match.head import (
    CONFIG_FILE,
    HEAD_FORMAT,
    HEAD_VERSION,
    STATE_FILE,
    ProjectionHead,
    prototypes,
    read_head_config,
    save_head,
)
from pin_match.metrics import auroc
from pin_match.train_config import TrainConfig, TrainingError, default_backbone

# ------------------------------------------------------------------------------------------ data


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
        raise TrainingError(f"feature store {store.root} holds no crop of the train split; build it for all splits "
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


# ------------------------------------------------------------------------------------------ loss


def batch_loss(head: ProjectionHead, scale: torch.Tensor, bias: torch.Tensor, data: TrainData,
               crop_idx: np.ndarray, cfg: TrainConfig) -> torch.Tensor:
    """The two BCE terms (see the module docstring) for one step's crops, all of one episode."""
    store = data.store
    episode = str(store.crops.episode_id.iloc[int(crop_idx[0])])
    query = [u for u in data.queries[episode] if u in data.fit_objects]
    tokens = torch.from_numpy(np.asarray(store.frames[crop_idx], np.float32))            # (B, P, D)
    obj = torch.from_numpy(np.asarray(store.patch_object[crop_idx], np.int64))           # (B, P)
    cover = torch.from_numpy(np.asarray(store.patch_cover[crop_idx], np.float32))        # (B, P)
    refs = torch.from_numpy(np.asarray(store.refs[query], np.float32))                   # (Q, V, P, D)
    alpha = torch.from_numpy(np.asarray(store.ref_alpha[query], np.float32))             # (Q, V, P)

    z = F.normalize(head(tokens), dim=-1)
    sims = torch.einsum("bpd,qvd->bpqv", z, prototypes(head, refs, alpha)).amax(-1)      # (B, P, Q)
    logits = scale * (sims - bias)

    on_held = torch.isin(obj, torch.tensor(sorted(data.holdout_objects), dtype=torch.int64))
    on_episode = torch.isin(obj, torch.tensor(data.queries[episode], dtype=torch.int64))
    sums, counts = torch.zeros(3), torch.zeros(3)  # positives, hard negatives, other negatives
    crop_sums, crop_counts = torch.zeros(3), torch.zeros(3)  # crops: query shown, only a sibling shown, neither
    for k, u in enumerate(query):
        lk, on_u = logits[..., k], obj == u
        groups = (on_u & (cover >= cfg.min_cover), on_episode & ~on_u & ~on_held, ~on_episode & ~on_held)
        for g, (mask, label) in enumerate(zip(groups, (1.0, 0.0, 0.0))):
            values = lk[mask]
            sums = sums.index_add(0, torch.tensor([g]), F.binary_cross_entropy_with_logits(
                values, torch.full_like(values, label), reduction="sum").reshape(1))
            counts[g] += values.numel()
        present, absent = groups[0].any(1), ~on_u.any(1)  # a crop where u shows only a sliver is left out
        sibling = absent & groups[1].any(1)
        crop_logit = lk.masked_fill(on_held, -1e4).amax(1)
        for g, (mask, label) in enumerate(zip((present, sibling, absent & ~sibling), (1.0, 0.0, 0.0))):
            values = crop_logit[mask]
            crop_sums = crop_sums.index_add(0, torch.tensor([g]), F.binary_cross_entropy_with_logits(
                values, torch.full_like(values, label), reduction="sum").reshape(1))
            crop_counts[g] += values.numel()
    return (sums / counts.clamp(min=1)).sum() + (crop_sums / crop_counts.clamp(min=1)).sum()


# ------------------------------------------------------------------------------------------ scoring from the store


@torch.inference_mode()
def store_crop_scores(store: FeatureStore, head: torch.nn.Module | None, crop_idx: np.ndarray,
                      objects: list[int], chunk: int = 64) -> np.ndarray:
    """(len(crop_idx), len(objects)) crop scores: max over patches of max over views of the cosine to the prototypes.

    With ``head=None`` this is the frozen prototype matcher's score, from the stored tokens.
    """
    head = head if head is not None else torch.nn.Identity()
    refs = torch.from_numpy(np.asarray(store.refs[objects], np.float32))
    alpha = torch.from_numpy(np.asarray(store.ref_alpha[objects], np.float32))
    protos = prototypes(head, refs, alpha)
    out = np.empty((len(crop_idx), len(objects)), np.float32)
    for start in range(0, len(crop_idx), chunk):
        idx = crop_idx[start:start + chunk]
        z = F.normalize(head(torch.from_numpy(np.asarray(store.frames[idx], np.float32))), dim=-1)
        out[start:start + len(idx)] = torch.einsum("bpd,qvd->bpqv", z, protos).amax(-1).amax(1).numpy()
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


def choose_sigma_on(scored: pd.DataFrame, objective: str) -> float:
    from pin_match.sweep import sweep
    from pin_match.tuning import choose_sigma

    curve = sweep(scored)
    index, _ = choose_sigma(curve, objective)
    return float(curve["sigma"].iloc[index])


# ------------------------------------------------------------------------------------------ the loop


@contextmanager
def deterministic(threads: int):
    """Deterministic torch algorithms and a fixed thread count for the block; the caller's settings come back."""
    old_threads, old_det = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(threads)
    torch.use_deterministic_algorithms(True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(old_det)
        torch.set_num_threads(old_threads)


def _params(head: ProjectionHead, scale: torch.Tensor, bias: torch.Tensor) -> list[torch.Tensor]:
    return [*head.parameters(), scale, bias]


def _save_state(out: Path, run: dict, head: ProjectionHead, best: dict[str, torch.Tensor], scale: torch.Tensor,
                bias: torch.Tensor, opt: torch.optim.Optimizer, progress: dict) -> None:
    """Everything a resumed run needs, in one file written atomically (so it is always self-consistent)."""
    from safetensors.torch import save

    tensors = {f"head.{k}": v.detach().clone() for k, v in head.state_dict().items()}
    tensors.update({f"best.{k}": v.clone() for k, v in best.items()})
    tensors["scale"], tensors["bias"] = scale.detach().clone(), bias.detach().clone()
    for i, p in enumerate(_params(head, scale, bias)):
        for key, value in opt.state.get(p, {}).items():
            tensors[f"opt.{i}.{key}"] = value.detach().clone()
    meta = dict(run=json.dumps(run, sort_keys=True), progress=json.dumps(progress))
    atomic.write_bytes(out / STATE_FILE, save({k: v.contiguous() for k, v in tensors.items()}, metadata=meta))


def _load_state(out: Path, run: dict, head: ProjectionHead, scale: torch.Tensor, bias: torch.Tensor,
                opt: torch.optim.Optimizer) -> tuple[dict, dict[str, torch.Tensor]] | None:
    from safetensors import safe_open

    path = out / STATE_FILE
    if not path.exists():
        return None
    with safe_open(str(path), "pt") as f:
        meta = f.metadata()
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    if json.loads(meta["run"]) != json.loads(json.dumps(run, sort_keys=True)):
        raise TrainingError(f"{out} holds a run of another configuration, backbone or frame-set; choose another "
                            f"--out or delete {out}")
    head.load_state_dict({k[5:]: v for k, v in tensors.items() if k.startswith("head.")})
    with torch.no_grad():
        scale.copy_(tensors["scale"])
        bias.copy_(tensors["bias"])
    for i, p in enumerate(_params(head, scale, bias)):
        state = {k.split(".", 2)[2]: v for k, v in tensors.items() if k.startswith(f"opt.{i}.")}
        if state:
            opt.state[p] = state
    return json.loads(meta["progress"]), {k[5:]: v for k, v in tensors.items() if k.startswith("best.")}


def find_store(fs: FrameSet, backbone: str, overrides: dict, features: str | Path, progress: bool) -> FeatureStore:
    """The store of this backbone config and frame-set (all splits, else the train split), built when absent."""
    matcher = patch_matcher(backbone, overrides)
    base = store_dir(features, matcher, fs)
    for split in ("all", "train"):
        if (base / split / "store.json").exists():
            return FeatureStore.open(base / split, fs)
    return build_features(fs, backbone, overrides=overrides, out=features, progress=progress)


def _head_config(run: dict, store: FeatureStore, fs: FrameSet, data: TrainData, cfg: TrainConfig,
                 progress: dict, finished: bool) -> dict:
    import pin_match

    return dict(format=HEAD_FORMAT, version=HEAD_VERSION, head=dict(kind="residual-mlp", dim=store.dim,
                                                                      hidden=cfg.hidden),
                backbone=run["backbone"], backbone_cfg=run["backbone_cfg"], backbone_id=store.backbone_id,
                crops=store.meta.get("crops_policy"), frameset_fingerprint=fs.fingerprint, frameset_root=str(fs.root),
                seed=cfg.seed, pin_match_version=pin_match.__version__, sigma=progress["sigma"],
                sigma_source=f"{cfg.objective} on the held-out train objects, best epoch"
                if progress["sigma"] is not None else "none yet: the run is unfinished",
                fit_objects=[store.objects[i] for i in sorted(data.fit_objects)],
                holdout_objects=[store.objects[i] for i in sorted(data.holdout_objects)],
                best_epoch=progress["best_epoch"], epochs_run=progress["epoch"], history=progress["history"],
                finished=finished, train=run["train"], run=json.loads(json.dumps(run)),
                written=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))


def train(frameset: FrameSet | str | Path, out: str | Path, *, backbone: str | None = None,
          overrides: dict[str, Any] | None = None, features: str | Path = DEFAULT_OUT,
          cfg: TrainConfig | None = None, store: FeatureStore | None = None, progress: bool = True,
          stop_after: int | None = None) -> dict:
    """Train (or resume, or find finished) a head in ``out``; returns its config.json content.

    After every epoch the folder is a usable head (best epoch so far) and holds the state
    a killed run resumes from. ``stop_after`` ends this call once that many epochs are
    done in total, as a kill would (the next call resumes); tests and budgeted runs use it.
    """
    from tqdm.auto import tqdm

    cfg = cfg or TrainConfig()
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    check_trainable(fs)  # before any backbone is built
    backbone = backbone or default_backbone()
    overrides = dict(overrides or {})
    if store is None:
        store = find_store(fs, backbone, overrides, features, progress)
    elif store.meta["frameset_fingerprint"] != fs.fingerprint:
        raise TrainingError(f"feature store {store.root} was built for frame-set {store.meta['frameset_root']} "
                            f"({store.meta['frameset_fingerprint']}), not for {fs.root} ({fs.fingerprint})")
    data = prepare_data(fs, store, cfg)
    store.meta["categories"] = [str(c) for c in fs.objects.set_index("object_id").category.reindex(store.objects)]
    out = Path(out)
    run = json.loads(json.dumps(dict(train=dataclasses.asdict(cfg), backbone=backbone, backbone_cfg=overrides,
                                     backbone_id=store.backbone_id, frameset_fingerprint=fs.fingerprint,
                                     dim=store.dim)))
    if (out / CONFIG_FILE).exists() and (out / STATE_FILE).exists():
        done = read_head_config(out)
        if done.get("finished") and done.get("run") == run:
            return done
    atomic.ensure_dir(out)

    with deterministic(cfg.threads), torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.seed)
        head = ProjectionHead(store.dim, cfg.hidden)
        scale = torch.nn.Parameter(torch.tensor(10.0))
        bias = torch.nn.Parameter(torch.tensor(0.5))
        opt = torch.optim.AdamW(_params(head, scale, bias), lr=cfg.lr, weight_decay=cfg.weight_decay)
        resumed = _load_state(out, run, head, scale, bias, opt)
        if resumed is None:
            held = query_frames(data, None, data.holdout_objects, relevant_only=True)  # epoch 0: the frozen matcher
            state = dict(epoch=0, best_epoch=0, sigma=None,
                         history=[dict(epoch=0, loss=None, val_auroc=validation_auroc(held), seconds=0.0)])
            best = {k: v.detach().clone() for k, v in head.state_dict().items()}
        else:
            state, best = resumed
        bar = tqdm(total=cfg.epochs, initial=state["epoch"], desc=f"train {out.name}", unit="epoch",
                   disable=not progress)
        bar.set_postfix(val_auroc=f"{state['history'][-1]['val_auroc']:.3f}")
        interrupted = False
        while state["epoch"] < cfg.epochs and state["epoch"] - state["best_epoch"] < cfg.patience:
            if stop_after is not None and state["epoch"] >= stop_after:
                interrupted = True
                break
            epoch = state["epoch"] + 1
            t0 = dt.datetime.now()
            head.train()
            losses = []
            for crop_idx in epoch_batches(data, cfg, epoch):
                loss = batch_loss(head, scale, bias, data, crop_idx, cfg)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                losses.append(float(loss.detach()))
            head.eval()
            val = validation_auroc(query_frames(data, head, data.holdout_objects, relevant_only=True))
            state["history"].append(dict(epoch=epoch, loss=float(np.mean(losses)) if losses else None,
                                         val_auroc=val, seconds=round((dt.datetime.now() - t0).total_seconds(), 2)))
            state["epoch"] = epoch
            if val > state["history"][state["best_epoch"]]["val_auroc"]:
                state["best_epoch"] = epoch
                best = {k: v.detach().clone() for k, v in head.state_dict().items()}
            _save_state(out, run, head, best, scale, bias, opt, state)
            _write_head(out, best, store, run, fs, data, cfg, state, finished=False)
            bar.update(1)
            bar.set_postfix(loss=f"{state['history'][-1]['loss']:.4f}", val_auroc=f"{val:.3f}")
        bar.close()
        if not interrupted:  # sigma once, on every frame of the held-out objects' episodes, with the best head
            final = ProjectionHead(store.dim, cfg.hidden)
            final.load_state_dict(best)
            state["sigma"] = choose_sigma_on(query_frames(data, final.eval(), data.holdout_objects), cfg.objective)
        if resumed is None and state["epoch"] == 0:
            _save_state(out, run, head, best, scale, bias, opt, state)
        return _write_head(out, best, store, run, fs, data, cfg, state, finished=not interrupted)


def _write_head(out: Path, best: dict[str, torch.Tensor], store: FeatureStore, run: dict, fs: FrameSet,
                data: TrainData, cfg: TrainConfig, state: dict, finished: bool) -> dict:
    head = ProjectionHead(store.dim, cfg.hidden)
    head.load_state_dict(best)
    config = _head_config(run, store, fs, data, cfg, state, finished)
    save_head(out, head, config)
    return config


# ------------------------------------------------------------------------------------------ learned vs frozen


def scored_from_store(fs: FrameSet, store: FeatureStore, head: torch.nn.Module | None, name: str) -> pd.DataFrame:
    """Frame labels with the store-based score of every stored frame (the metrics' input), as scoring would give."""
    from pin_match.labels import frame_labels, scored_frames
    from pin_match.scoretable import ScoreTable

    scores = store_frame_scores(store, fs, head)
    return scored_frames(frame_labels(fs), ScoreTable(scores, dict(matcher=name, matcher_id=name)))


def tuned_sigma(scored: pd.DataFrame, objective: str = "first-match", split: str = "train") -> float:
    """Sigma chosen on one split of scored frames, as ``pin-match tune`` chooses it."""
    part = scored[scored.split == split]
    if part.empty:
        raise TrainingError(f"no scored frames of split {split!r} to tune sigma on")
    return choose_sigma_on(part, objective)


def compare_with_frozen(fs: FrameSet, store: FeatureStore, head: torch.nn.Module, sigmas: dict[str, float],
                        split: str = "val") -> dict:
    """Learned head vs the frozen prototype matcher of the same store on one split, at given sigmas.

    Returns per matcher ("frozen", "learned"): the scored frames of the split, the detection
    metrics at its sigma (AUROC target vs same-category is ``auroc_same``) and the
    per-category table.
    """
    from pin_match.metrics import detection_metrics, per_category

    out: dict[str, dict] = {}
    for name, h in (("frozen", None), ("learned", head)):
        scored = scored_from_store(fs, store, h, name)
        scored = scored[scored.split == split].reset_index(drop=True)
        if scored.empty:
            raise TrainingError(f"feature store {store.root} holds no frame of split {split!r}")
        out[name] = dict(scored=scored, sigma=sigmas[name], metrics=detection_metrics(scored, sigmas[name]),
                         per_category=per_category(scored, sigmas[name]))
    return out
