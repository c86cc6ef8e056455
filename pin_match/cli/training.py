"""The learning half of the CLI: ``features`` (frozen patch tokens, once) and ``train`` (a head on them)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pin_match.cli.args import add_matcher_config, matcher_overrides


def _cmd_features(a: argparse.Namespace) -> None:
    from pin_match.training.features import build_features

    store = build_features(a.frameset, a.backbone, overrides=matcher_overrides(a), out=a.out, split=a.split,
                           batch_size=a.batch_size, progress=not a.quiet)
    m = store.meta
    print(f"{m['matcher_id']}: {m['n_frames']} frames ({m['n_crops']} crops, {m['grid']}x{m['grid']} patches of "
          f"{m['dim']} dims), {len(m['objects'])} objects; {m['frames_per_second']:.3g} frames/s when built "
          f"-> {store.root}")


def _cmd_train(a: argparse.Namespace) -> None:
    from pin_match.training import TrainConfig, train

    cfg = TrainConfig(hidden=a.hidden, epochs=a.epochs, patience=a.patience, batch_crops=a.batch_crops, lr=a.lr,
                      holdout=a.holdout, seed=a.seed, threads=a.threads, objective=a.objective)
    config = train(a.frameset, a.out, backbone=a.backbone, overrides=matcher_overrides(a), features=a.features,
                   cfg=cfg, progress=not a.quiet)
    best = config["history"][config["best_epoch"]]
    frozen = config["history"][0]
    print(f"head on {config['backbone_id']}: best epoch {config['best_epoch']} of {config['epochs_run']}, held-out "
          f"AUROC target vs same-category {best['val_auroc']:.3f} (frozen {frozen['val_auroc']:.3f}), sigma "
          f"{config['sigma']:.4g} -> {a.out}\nscore with: pin-match score FRAMESET --matcher learned --weights {a.out}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    from pin_match.evaluation.tuning import OBJECTIVES
    from pin_match.training.config import TrainConfig
    from pin_match.training.features import DEFAULT_OUT

    defaults = TrainConfig()
    for name in ("features", "train"):
        helptext = ("compute a patch backbone's frozen tokens of every frame crop and reference once (float16, "
                    "memory-mapped)" if name == "features" else
                    "train a projection head on the train split against same-category look-alikes")
        s = sub.add_parser(name, help=helptext)
        s.add_argument("frameset", type=Path, help="frame-set folder (training needs its train split)")
        s.add_argument("--backbone", required=name == "features",
                       help="registered patch matcher whose backbone is used: effnet, dino, dinov2, clip"
                            + (" (default: effnet when installed, else dino)" if name == "train" else ""))
        add_matcher_config(s, "the backbone matcher's")
        s.add_argument("--quiet", action="store_true", help="no progress bar")
        if name == "features":
            s.add_argument("--out", type=Path, default=DEFAULT_OUT,
                           help=f"store root; the store goes to OUT/<backbone id>/<frame-set fingerprint>/ "
                                f"(default {DEFAULT_OUT})")
            s.add_argument("--split", help="store only this split's frames (default: all)")
            s.add_argument("--batch-size", type=int, default=8, help="frames per backbone batch (default 8)")
            s.set_defaults(func=_cmd_features)
            continue
        s.add_argument("--out", type=Path, required=True, help="head folder to write, e.g. heads/NAME; a killed run "
                                                               "resumes from its last epoch")
        s.add_argument("--features", type=Path, default=DEFAULT_OUT,
                       help=f"feature store root (built there when absent; default {DEFAULT_OUT})")
        s.add_argument("--epochs", type=int, default=defaults.epochs, help=f"at most this many epochs "
                                                                           f"(default {defaults.epochs})")
        s.add_argument("--patience", type=int, default=defaults.patience,
                       help=f"stop after this many epochs without a better held-out AUROC (default "
                            f"{defaults.patience})")
        s.add_argument("--hidden", type=int, default=defaults.hidden, help=f"hidden width of the head (default "
                                                                           f"{defaults.hidden})")
        s.add_argument("--batch-crops", type=int, default=defaults.batch_crops,
                       help=f"crops per step, from one episode (default {defaults.batch_crops})")
        s.add_argument("--lr", type=float, default=defaults.lr, help=f"AdamW learning rate (default {defaults.lr})")
        s.add_argument("--holdout", type=float, default=defaults.holdout,
                       help=f"share of each category's train objects held out for early stopping and sigma "
                            f"(default {defaults.holdout})")
        s.add_argument("--seed", type=int, default=defaults.seed, help=f"seed of the head and the batch order "
                                                                       f"(default {defaults.seed})")
        s.add_argument("--threads", type=int, default=defaults.threads,
                       help=f"torch CPU threads, fixed for bit-identical results (default {defaults.threads})")
        s.add_argument("--objective", default=defaults.objective, choices=sorted(OBJECTIVES),
                       help=f"how sigma is chosen on the held-out objects (default {defaults.objective})")
        s.set_defaults(func=_cmd_train)
