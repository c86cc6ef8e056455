"""The learning half of the CLI: ``features`` (frozen patch tokens, once) and ``train`` (a head on them)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pin_match.cli.args import (
    add_dataclass_flags,
    add_matcher_config,
    add_run_options,
    add_scheduler,
    dataclass_values,
    engine_run,
    matcher_overrides,
    run_options,
)


def _cmd_features(a: argparse.Namespace) -> None:
    from pin_match.training.features import build_features

    with engine_run(a) as run:
        store = build_features(a.frameset, a.backbone, overrides=matcher_overrides(a), out=a.out, split=a.split,
                               run=run)
    print(f"{store.backbone_id}: {store.crops.frame_id.nunique()} frames ({len(store.crops)} crops, {store.grid}x"
          f"{store.grid} patches of {store.dim} dims), {len(store.objects)} objects -> {store.path}")


def _cmd_train(a: argparse.Namespace) -> None:
    from pin_match.training import Backbone, TrainConfig, default_backbone, train

    backbone = Backbone(a.backbone or default_backbone(), matcher_overrides(a))
    config = train(a.frameset, a.out, backbone=backbone, features=a.features,
                   cfg=dataclass_values(a, TrainConfig), progress=run_options(a).progress)
    best = config["history"][config["best_epoch"]]
    frozen = config["history"][0]
    print(f"head on {config['backbone_id']}: best epoch {config['best_epoch']} of {config['epochs_run']}, held-out "
          f"AUROC target vs same-category {best['val_auroc']:.3f} (frozen {frozen['val_auroc']:.3f}), sigma "
          f"{config['sigma']:.4g} -> {a.out}\nscore with: pin-match score FRAMESET --matcher learned --weights {a.out}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    from pin_match.evaluation.core.tuning import OBJECTIVES
    from pin_match.outputs import FEATURES
    from pin_match.training.config import TrainConfig

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
        if name == "features":
            add_run_options(s, workers="threads decoding frames (default up to 2); with --scheduler local, worker "
                                       "processes")
            add_scheduler(s)
            s.add_argument("--out", type=Path, default=FEATURES,
                           help=f"store root; the store goes to OUT/features-<backbone id>/<frame-set fingerprint>/ "
                                f"(default {FEATURES})")
            s.add_argument("--split", help="store only this split's frames (default: all)")
            s.set_defaults(func=_cmd_features)
            continue
        add_run_options(s, workers=None, batch_size=False)
        s.add_argument("--out", type=Path, required=True, help="head folder to write, e.g. heads/NAME; a killed run "
                                                               "resumes from its last epoch")
        s.add_argument("--features", type=Path, default=FEATURES,
                       help=f"feature store root (built there when absent; default {FEATURES})")
        add_dataclass_flags(s, TrainConfig, choices={"objective": sorted(OBJECTIVES)})
        s.set_defaults(func=_cmd_train)
