"""What a training run writes: the resume state (one file, atomic) and the head folder after every epoch."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import torch

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.nn.head import HEAD_FORMAT, HEAD_VERSION, STATE_FILE, ProjectionHead, save_head
from pin_match.training.config import TrainConfig, TrainingError
from pin_match.training.data import TrainData
from pin_match.training.features import FeatureStore


def params(head: ProjectionHead, scale: torch.Tensor, bias: torch.Tensor) -> list[torch.Tensor]:
    return [*head.parameters(), scale, bias]


def save_state(out: Path, run: dict, head: ProjectionHead, best: dict[str, torch.Tensor], scale: torch.Tensor,
                bias: torch.Tensor, opt: torch.optim.Optimizer, progress: dict) -> None:
    """Everything a resumed run needs, in one file written atomically (so it is always self-consistent)."""
    from safetensors.torch import save

    tensors = {f"head.{k}": v.detach().clone() for k, v in head.state_dict().items()}
    tensors.update({f"best.{k}": v.clone() for k, v in best.items()})
    tensors["scale"], tensors["bias"] = scale.detach().clone(), bias.detach().clone()
    for i, p in enumerate(params(head, scale, bias)):
        for key, value in opt.state.get(p, {}).items():
            tensors[f"opt.{i}.{key}"] = value.detach().clone()
    meta = dict(run=json.dumps(run, sort_keys=True), progress=json.dumps(progress))
    atomic.write_bytes(out / STATE_FILE, save({k: v.contiguous() for k, v in tensors.items()}, metadata=meta))


def load_state(out: Path, run: dict, head: ProjectionHead, scale: torch.Tensor, bias: torch.Tensor,
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
    for i, p in enumerate(params(head, scale, bias)):
        state = {k.split(".", 2)[2]: v for k, v in tensors.items() if k.startswith(f"opt.{i}.")}
        if state:
            opt.state[p] = state
    return json.loads(meta["progress"]), {k[5:]: v for k, v in tensors.items() if k.startswith("best.")}


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


def write_head(out: Path, best: dict[str, torch.Tensor], store: FeatureStore, run: dict, fs: FrameSet,
                data: TrainData, cfg: TrainConfig, state: dict, finished: bool) -> dict:
    head = ProjectionHead(store.dim, cfg.hidden)
    head.load_state_dict(best)
    config = _head_config(run, store, fs, data, cfg, state, finished)
    save_head(out, head, config)
    return config
