"""``cohort-norm``: any matcher's score read against a cohort of other real instances (adaptive Z-norm).

At ``prepare`` the ``base`` matcher, prepared for the target, scores every image of the cohort
(images of other real objects, each one frame); the ``k`` highest of those scores give the target
its own impostor scale (``contract.cohort.TargetCohort``: ``k`` 0 takes them all, plain Z-norm), and
every score the base returns for a frame, its crops, points and boxes is read against it
(``normalised``: 0.5 is the cohort's top-k mean, in [0, 1] and monotone, so the base's ranking
within a target is kept and its points above sigma are the same points). The default cohort is
the 59 CORe50 photos shipped with pin_match (10 household categories, CC BY 4.0); ``weights=DIR``
names another folder of images, whose content enters the id. What it assumes: a target's
look-alikes in the house score like its closest cohort members; where the cohort holds nothing
like them (another domain, other categories), the scale is a generic one (docs/instance-matchers.md).
Each target's cohort (every member's score, the scale) goes into the score table as its notes,
so the report shows it beside the target's scores. Cost: a base pass per cohort image at every
``prepare`` (one for every variant prepared with the same base, target and cohort), nothing more a
frame: the base's results on a batch of frames are the batch's (``contract.frames``), so variants
scored together, and the base scored beside them, run it once.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from pin_match.contract import (
    ConfigError,
    Frames,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    Target,
    WeightsError,
    WeightsSpec,
    register_matcher,
    weights_field,
)
from pin_match.contract.cohort import TargetCohort
from pin_match.matchers.common.composite import CompositeMatcher, part_cfg_field

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
COHORT_BATCH = 8
KEPT_COHORTS = 16  # cohort scores kept (a base and a target each): a run prepares its variants of a target in turn
_COHORT_SCORES: dict[tuple, tuple[float, ...]] = {}
_COHORT_LOCK = threading.Lock()


@dataclass
class CohortNormConfig(MatcherConfig):
    """The base matcher, how many cohort members set the scale; ``weights`` is the cohort's folder of images."""

    weights: str | None = weights_field()
    base: str = field(default="verify", metadata={"help": "the matcher whose scores are normalised"})
    base_cfg: dict[str, Any] = part_cfg_field("base")
    k: int = field(default=5, metadata={"help": "cohort members with the highest scores that set the scale "
                                                "(adaptive Z-norm); 0: all of them (Z-norm)"})
    min_std: float = field(default=0.25, metadata={"help": "smallest spread of the cohort's scores"})
    probability: bool = field(default=True, metadata={
        "help": "the base's score is a probability (normalised in the logit domain); false: as it is"})

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.k < 0 or self.min_std <= 0:
            raise ConfigError(f"{type(self).__name__}: k must be >= 0 and min_std > 0")


@register_matcher("cohort-norm")
class CohortNormMatcher(CompositeMatcher):
    """A base matcher's scores on the scale of its own scores of a cohort of other real instances."""

    Config = CohortNormConfig
    modality = Modality.VISUAL
    weights_spec = WeightsSpec(package="pin_match", package_file="data/sources/lookalike_src/photos",
                               distribution="pin-match",
                               license="CC BY 4.0 (CORe50, Lomonaco & Maltoni 2017; the folder's NOTICE.md)")
    # untuned: the cohort's top-k mean (sigmas chosen leaving one set out were about 0.99 with verify as base;
    # docs/instance-matchers.md): tune it on frames like the agent's
    default_sigma = 0.5
    version = 1
    paper = ("cohort score normalisation of speaker verification: Z-norm (Auckenthaler et al., DSP 2000), "
             "adaptive cohort (Sturim and Reynolds, ICASSP 2005)")

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self.base = self.add_part("base", self.cfg.base, self.cfg.base_cfg)
        self.require_visual()
        self._cohort: TargetCohort | None = None

    @property
    def cohort_folder(self) -> Path:
        return Path(self.cfg.weights).expanduser() if self.cfg.weights else self.weights_spec.carried_file()

    @property
    def cohort_files(self) -> tuple[tuple[str, int, int], ...]:
        """The cohort's images as (path, modification time, size): what its images and scores are read again on."""
        folder = self.cohort_folder
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES) if folder.is_dir() else []
        if not files:
            raise WeightsError(f"matcher {self.display_name}: the cohort folder {folder} holds no images "
                               f"({', '.join(IMAGE_SUFFIXES)})")
        return tuple((str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in files)

    @property
    def cohort_images(self) -> dict[str, np.ndarray]:
        """The cohort's images by file name, RGB: read once per process and folder state."""
        return _read_cohort(self.cohort_files)

    @property
    def score_scale(self) -> str:
        how = f"adaptive Z-norm over the {self.cfg.k} closest members" if self.cfg.k else "Z-norm over all members"
        where = self.cfg.weights or "the CORe50 photos shipped with pin_match"
        return (f"cohort-normalised: {self.cfg.base}'s score read against its scores of a cohort of other objects "
                f"({how}; cohort {where}); 0.5 is the cohort's mean")

    def _prepare(self, target: Target) -> None:
        super()._prepare(target)
        files = self.cohort_files  # the folder listed once
        names = [Path(path).name for path, _, _ in files]
        cfg = self.cfg
        self._cohort = TargetCohort.of(str(self.cohort_folder), names, self._cohort_scores(files), k=cfg.k,
                                       min_std=cfg.min_std, probability=cfg.probability)

    def _cohort_scores(self, files: tuple[tuple[str, int, int], ...]) -> tuple[float, ...]:
        """The base's score of each cohort image for the prepared target. Kept by the base's ``share_key`` (id,
        device, target) and the folder's state, the last ``KEPT_COHORTS`` of a process, so the variants of this
        matcher (other ``k``, ``min_std``, ``probability``) that a run prepares alike score the cohort once."""
        key = (self.base.share_key, files)
        with _COHORT_LOCK:  # a Dask worker prepares in several threads
            found = _COHORT_SCORES.get(key)
        if found is None:
            images = list(_read_cohort(files).values())
            found = tuple(r.score for i in range(0, len(images), COHORT_BATCH)
                          for r in self.base.match_batch(images[i:i + COHORT_BATCH]))
            with _COHORT_LOCK:
                _COHORT_SCORES[key] = found
                while len(_COHORT_SCORES) > KEPT_COHORTS:
                    del _COHORT_SCORES[next(iter(_COHORT_SCORES))]
        return found

    @property
    def cohort(self) -> TargetCohort:
        """The prepared target's cohort: its members' scores and the scale they give."""
        if self._cohort is None:
            raise MatcherError(f"matcher {self.display_name}: call prepare(target) first")
        return self._cohort

    def target_notes(self) -> dict[str, Any]:
        return self.cohort.as_notes()

    def _match_batch(self, frames: Frames) -> list[MatchResult]:
        norm = self.cohort.impostors.normalised
        out = []
        for r in frames.results(self.base):
            out.append(dataclasses.replace(
                r, score=float(norm(r.score)), point_scores=_mapped(norm, r.scores_of_points()),
                crop_scores=_mapped(norm, r.crop_scores), box_scores=_mapped(norm, r.box_scores)))
        return out


@lru_cache(maxsize=4)
def _read_cohort(files: tuple[tuple[str, int, int], ...]) -> dict[str, np.ndarray]:
    """The images of ``files`` (path, modification time, size) by file name; read-only, as they are shared."""
    images = {}
    for path, _, _ in files:
        bgr = cv2.imread(path, cv2.IMREAD_COLOR)
        if bgr is None:
            raise WeightsError(f"matcher cohort-norm: cannot read the cohort image {path}")
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        rgb.flags.writeable = False
        images[Path(path).name] = rgb
    return images


def _mapped(norm, values: np.ndarray | None) -> np.ndarray | None:
    return None if values is None else np.asarray(norm(np.asarray(values, np.float64)), np.float32)
