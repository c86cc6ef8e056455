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
from pathlib import Path

import numpy as np
import torch

from pin_match import atomic, outputs
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.tuning import sigma_for
from pin_match.matchers.common.patch import patch_matcher
from pin_match.nn.head import CONFIG_FILE, STATE_FILE, ProjectionHead, read_head_config
from pin_match.scoring.options import RunOptions
from pin_match.training.checkpoint import Trainable, TrainRun, load_state, save_state, write_head
from pin_match.training.config import Backbone, TrainConfig, TrainingError
from pin_match.training.data import TrainData, check_trainable, epoch_batches, prepare_data
from pin_match.training.features import FeatureStore, build_features, store_path
from pin_match.training.loss import batch_loss
from pin_match.training.store_scores import query_frames, validation_auroc


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


def find_store(fs: FrameSet, backbone: Backbone, features: str | Path, progress: bool) -> FeatureStore:
    """The store of this backbone config and frame-set (all splits, else the train split), built when absent."""
    matcher = patch_matcher(backbone.name, **backbone.overrides)
    for split in (None, "train"):
        path = store_path(features, matcher, fs, split)
        if path.exists():
            return FeatureStore.open(path, fs)
    return build_features(fs, backbone.name, overrides=backbone.overrides, out=features,
                          run=RunOptions(progress=progress))


def train(frameset: FrameSet | str | Path, out: str | Path, *, backbone: Backbone | None = None,
          features: str | Path | FeatureStore = outputs.FEATURES, cfg: TrainConfig | None = None,
          progress: bool = True, stop_after: int | None = None) -> dict:
    """Train (or resume, or find finished) a head in ``out``; returns its config.json content.

    ``features`` is the folder of feature stores (this backbone's store for the frame-set is found
    or built there) or an opened store. After every epoch the folder is a usable head (best epoch
    so far) and holds the state a killed run resumes from. ``stop_after`` ends this call once that
    many epochs are done in total, as a kill would (the next call resumes); tests and budgeted runs
    use it.
    """
    cfg = cfg or TrainConfig()
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    check_trainable(fs)  # before any backbone is built
    backbone = backbone or Backbone()
    store = features if isinstance(features, FeatureStore) else find_store(fs, backbone, features, progress)
    if store.meta["frameset_fingerprint"] != fs.fingerprint:
        raise TrainingError(f"feature store {store.path} was built for frame-set {store.meta['frameset_name']!r} "
                            f"({store.meta['frameset_fingerprint']}), not for {fs.root} ({fs.fingerprint})")
    data = prepare_data(fs, store, cfg)
    store.meta["categories"] = [str(c) for c in fs.objects.set_index("object_id").category.reindex(store.objects)]
    run = json.loads(json.dumps(dict(train=dataclasses.asdict(cfg), backbone=backbone.name,
                                     backbone_cfg=dict(backbone.overrides), backbone_id=store.backbone_id,
                                     frameset_fingerprint=fs.fingerprint, dim=store.dim)))
    job = TrainRun(Path(out), run, fs, store, data, cfg)
    if (job.out / CONFIG_FILE).exists() and (job.out / STATE_FILE).exists():
        done = read_head_config(job.out)
        if done.get("finished") and done.get("run") == run:
            return done
    atomic.ensure_dir(job.out)
    with deterministic(cfg.threads), torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.seed)
        return _train_epochs(job, Trainable.new(store.dim, cfg), progress, stop_after)


def _train_epochs(job: TrainRun, model: Trainable, progress: bool, stop_after: int | None) -> dict:
    """Resume or start ``model``, run epochs until done, patience runs out or ``stop_after``; write the head."""
    from tqdm.auto import tqdm

    data, cfg = job.data, job.cfg
    resumed = load_state(job, model)
    if resumed is None:
        held = query_frames(data, None, data.holdout_objects, relevant_only=True)  # epoch 0: the frozen matcher
        state = dict(epoch=0, best_epoch=0, sigma=None,
                     history=[dict(epoch=0, loss=None, val_auroc=validation_auroc(held), seconds=0.0)])
        best = {k: v.detach().clone() for k, v in model.head.state_dict().items()}
    else:
        state, best = resumed
    bar = tqdm(total=cfg.epochs, initial=state["epoch"], desc=f"train {job.out.name}", unit="epoch",
               disable=not progress)
    bar.set_postfix(val_auroc=f"{state['history'][-1]['val_auroc']:.3f}")
    interrupted = False
    while state["epoch"] < cfg.epochs and state["epoch"] - state["best_epoch"] < cfg.patience:
        if stop_after is not None and state["epoch"] >= stop_after:
            interrupted = True
            break
        epoch = state["epoch"] + 1
        state["history"].append(_run_epoch(model, data, cfg, epoch))
        state["epoch"] = epoch
        val = state["history"][-1]["val_auroc"]
        if val > state["history"][state["best_epoch"]]["val_auroc"]:
            state["best_epoch"] = epoch
            best = {k: v.detach().clone() for k, v in model.head.state_dict().items()}
        save_state(job, model, best, state)
        write_head(job, best, state, finished=False)
        bar.update(1)
        bar.set_postfix(loss=f"{state['history'][-1]['loss']:.4f}", val_auroc=f"{val:.3f}")
    bar.close()
    if not interrupted:  # sigma once, on every frame of the held-out objects' episodes, with the best head
        final = ProjectionHead(job.store.dim, cfg.hidden)
        final.load_state_dict(best)
        state["sigma"] = sigma_for(query_frames(data, final.eval(), data.holdout_objects), cfg.objective)
    if resumed is None and state["epoch"] == 0:
        save_state(job, model, best, state)
    return write_head(job, best, state, finished=not interrupted)


def _run_epoch(model: Trainable, data: TrainData, cfg: TrainConfig, epoch: int) -> dict:
    """One pass over the epoch's batches, then the held-out AUROC; returns the epoch's history entry."""
    t0 = dt.datetime.now()
    model.head.train()
    losses = []
    for crop_idx in epoch_batches(data, cfg, epoch):
        loss = batch_loss(model.head, model.scale, model.bias, data, crop_idx, cfg)
        model.opt.zero_grad(set_to_none=True)
        loss.backward()
        model.opt.step()
        losses.append(float(loss.detach()))
    model.head.eval()
    val = validation_auroc(query_frames(data, model.head, data.holdout_objects, relevant_only=True))
    return dict(epoch=epoch, loss=float(np.mean(losses)) if losses else None, val_auroc=val,
                seconds=round((dt.datetime.now() - t0).total_seconds(), 2))
