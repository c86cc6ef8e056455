"""What a training run writes: the resume state (one file, atomic) and the head folder after every epoch."""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import dataclass
from pathlib import Path

import torch

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.nn.head import HEAD_FORMAT, HEAD_VERSION, STATE_FILE, ProjectionHead, save_head
from pin_match.training.config import TrainConfig, TrainingError
from pin_match.training.data import TrainData
from pin_match.training.features import FeatureStore


@dataclass
class Trainable:
    """What the optimiser changes: the head, the logits' scale and bias, and the optimiser holding their state."""

    head: ProjectionHead
    scale: torch.Tensor
    bias: torch.Tensor
    opt: torch.optim.Optimizer

    @classmethod
    def new(cls, dim: int, cfg: TrainConfig) -> Trainable:
        """A fresh head (initialised from torch's current seed), scale 10, bias 0.5, and its AdamW."""
        head = ProjectionHead(dim, cfg.hidden)
        scale = torch.nn.Parameter(torch.tensor(10.0))
        bias = torch.nn.Parameter(torch.tensor(0.5))
        opt = torch.optim.AdamW([*head.parameters(), scale, bias], lr=cfg.lr, weight_decay=cfg.weight_decay)
        return cls(head, scale, bias, opt)

    def params(self) -> list[torch.Tensor]:
        """The optimised tensors in the optimiser's order (the resume state's ``opt.<i>`` keys follow it)."""
        return [*self.head.parameters(), self.scale, self.bias]


@dataclass(frozen=True)
class TrainRun:
    """One run's fixed inputs: its folder, its identity (``run``, compared on resume), and what it trains on."""

    out: Path
    run: dict
    fs: FrameSet
    store: FeatureStore
    data: TrainData
    cfg: TrainConfig


def save_state(job: TrainRun, model: Trainable, best: dict[str, torch.Tensor], progress: dict) -> None:
    """Everything a resumed run needs, in one file written atomically (so it is always self-consistent)."""
    from safetensors.torch import save

    tensors = {f"head.{k}": v.detach().clone() for k, v in model.head.state_dict().items()}
    tensors.update({f"best.{k}": v.clone() for k, v in best.items()})
    tensors["scale"], tensors["bias"] = model.scale.detach().clone(), model.bias.detach().clone()
    for i, p in enumerate(model.params()):
        for key, value in model.opt.state.get(p, {}).items():
            tensors[f"opt.{i}.{key}"] = value.detach().clone()
    meta = dict(run=json.dumps(job.run, sort_keys=True), progress=json.dumps(progress))
    atomic.write_bytes(job.out / STATE_FILE, save({k: v.contiguous() for k, v in tensors.items()}, metadata=meta))


def load_state(job: TrainRun, model: Trainable) -> tuple[dict, dict[str, torch.Tensor]] | None:
    """Restore ``model`` from the run's resume state; returns (progress, best head) or None when there is none."""
    from safetensors import safe_open

    out = job.out
    path = out / STATE_FILE
    if not path.exists():
        return None
    with safe_open(str(path), "pt") as f:
        meta = f.metadata()
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    if json.loads(meta["run"]) != json.loads(json.dumps(job.run, sort_keys=True)):
        raise TrainingError(f"{out} holds a run of another configuration, backbone or frame-set; choose another "
                            f"--out or delete {out}")
    model.head.load_state_dict({k[5:]: v for k, v in tensors.items() if k.startswith("head.")})
    with torch.no_grad():
        model.scale.copy_(tensors["scale"])
        model.bias.copy_(tensors["bias"])
    for i, p in enumerate(model.params()):
        state = {k.split(".", 2)[2]: v for k, v in tensors.items() if k.startswith(f"opt.{i}.")}
        if state:
            model.opt.state[p] = state
    return json.loads(meta["progress"]), {k[5:]: v for k, v in tensors.items() if k.startswith("best.")}


def _head_config(job: TrainRun, progress: dict, finished: bool) -> dict:
    import pin_match

    run, store, data, cfg = job.run, job.store, job.data, job.cfg
    return dict(format=HEAD_FORMAT, version=HEAD_VERSION, head=dict(kind="residual-mlp", dim=store.dim,
                                                                      hidden=cfg.hidden),
                backbone=run["backbone"], backbone_cfg=run["backbone_cfg"], backbone_id=store.backbone_id,
                crops=store.meta.get("crops_policy"), frameset_fingerprint=job.fs.fingerprint,
                frameset_root=str(job.fs.root), seed=cfg.seed, pin_match_version=pin_match.__version__,
                sigma=progress["sigma"], sigma_source=f"{cfg.objective} on the held-out train objects, best epoch"
                if progress["sigma"] is not None else "none yet: the run is unfinished",
                fit_objects=[store.objects[i] for i in sorted(data.fit_objects)],
                holdout_objects=[store.objects[i] for i in sorted(data.holdout_objects)],
                best_epoch=progress["best_epoch"], epochs_run=progress["epoch"], history=progress["history"],
                finished=finished, train=run["train"], run=json.loads(json.dumps(run)),
                written=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))


def write_head(job: TrainRun, best: dict[str, torch.Tensor], progress: dict, finished: bool) -> dict:
    """The head folder (best epoch so far) with its config; returns the config."""
    head = ProjectionHead(job.store.dim, job.cfg.hidden)
    head.load_state_dict(best)
    config = _head_config(job, progress, finished)
    save_head(job.out, head, config)
    return config
