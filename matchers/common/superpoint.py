"""SuperPoint keypoints as magicleap's code keeps them (border band, then top-k), and the matchers built on them.

transformers' SuperGlue and LightGlue models carry a SuperPoint; the references' keypoints are
computed once per target, because the models' ``forward`` only pairs images of one size and would
run SuperPoint on every reference again for every frame. ``SuperPointGlueMatcher`` runs the
model's SuperPoint here (``detect``) and leaves the pairing to SuperGlue or LightGlue.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import cv2
import numpy as np
import torch

from pin_match.contract import MatcherConfig, WeightsSpec
from pin_match.matchers.common.keypoints import KeypointConfig, Keypoints, ReferenceKeypointMatcher


def border_and_top_k(xy: torch.Tensor, scores: torch.Tensor, border: int, height: int, width: int,
                     max_keypoints: int) -> torch.Tensor:
    """Indices of the keypoints SuperPoint keeps: ``border`` px from every edge of the score map, then the strongest.

    magicleap's SuperPoint removes the border band of the full-resolution score map
    (``height x width``, the image floored to a multiple of 8) and only then cuts to the top
    ``max_keypoints``. transformers (5.23, ``SuperPointInterestPointDecoder._extract_keypoints``)
    passes 8 x the full-resolution size as the bound, so its bottom and right bands survive and
    push other keypoints out of the top-k. ``detect`` therefore asks it for every keypoint and
    applies both rules here. On keypoints that already lack the band (a fixed transformers)
    the border test keeps everything, so the result does not depend on which one is installed.
    Ties at the cut are broken by ``torch.topk`` on the row-major order, as magicleap's code does.
    """
    x, y = xy[:, 0], xy[:, 1]
    inside = (y >= border) & (y < height - border) & (x >= border) & (x < width - border)
    kept = torch.nonzero(inside).flatten()
    if 0 <= max_keypoints < len(kept):
        kept = kept[torch.topk(scores[kept], max_keypoints, dim=0).indices]
    return kept


def detect(detector: torch.nn.Module, grays: Sequence[np.ndarray], device: str, max_keypoints: int) -> list[Keypoints]:
    """Run SuperPoint on same-size grayscale uint8 images (one batch), with magicleap's border and top-k rules.

    The detector must be built with ``max_keypoints=-1`` (``SuperPointGlueMatcher._configure_detector``): it returns
    every thresholded NMS maximum, and ``border_and_top_k`` keeps SuperPoint's. Descriptors are sampled per
    keypoint, so selecting rows afterwards gives the same descriptors as sampling only the kept keypoints.
    """
    h, w = grays[0].shape
    x = torch.from_numpy(np.stack(grays)).to(device=device, dtype=torch.float32)[:, None] / 255.0
    out = detector(x)
    size = torch.tensor([w, h], dtype=torch.float32, device=device)
    border = detector.config.border_removal_distance
    found = []
    for kp, sc, de, mask in zip(out.keypoints, out.scores, out.descriptors, out.mask):
        n = int(mask.sum())  # SuperPoint pads after the real keypoints
        xy = (kp[:n] * size).round()
        kept = border_and_top_k(xy, sc[:n], border, h // 8 * 8, w // 8 * 8, max_keypoints)
        found.append(Keypoints(xy=xy[kept], scores=sc[:n][kept], descriptors=de[:n][kept], height=h, width=w))
    return found


@dataclass
class SuperPointConfig(KeypointConfig):
    """SuperPoint's own settings; ``max_keypoints=-1`` keeps every keypoint."""

    nms_radius: int = 4
    keypoint_threshold: float = 0.005


class SuperPointGlueMatcher(ReferenceKeypointMatcher):
    """transformers' SuperPoint keypoints of the grayscale frame matched against PIN's six prepared references.

    Subclasses name their transformers model (SuperPoint + a graph matcher, ``transformers_classes``)
    and pair one observation-reference pair with it.
    """

    Config = SuperPointConfig
    weights_spec: ClassVar[WeightsSpec]
    # transformers' config and model classes of the graph matcher, by name, so transformers loads with the model only
    transformers_classes: ClassVar[tuple[str, str]]

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self._model: torch.nn.Module | None = None

    def _from_pretrained(self, source: str) -> torch.nn.Module:
        """The model from a hub id or a save_pretrained folder, its SuperPoint set up by ``_configure_detector``."""
        import transformers

        config_class, model_class = (getattr(transformers, name) for name in self.transformers_classes)
        config = config_class.from_pretrained(source)
        self._configure_detector(config.keypoint_detector_config)
        return model_class.from_pretrained(source, config=config)

    @abstractmethod
    def _match_pair(self, obs: Keypoints, ref: Keypoints) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(matches0 (m,), matches1 (n,), confidence0 (m,)) of one pair, -1 = no match."""

    def _configure_detector(self, detector_config: Any) -> None:
        """SuperPoint reads these when it is built, so they go into the config before loading.

        It returns every keypoint (``max_keypoints=-1``): the border and top-k rules are ``detect``'s.
        """
        detector_config.nms_radius = self.cfg.nms_radius
        detector_config.keypoint_threshold = self.cfg.keypoint_threshold
        detector_config.max_keypoints = -1

    def _load(self) -> None:
        if self._model is None:
            model = self.weights_spec.load_pretrained(self.cfg.weights, f"matcher {self.display_name}",
                                                      self._from_pretrained)
            self._model = model.to(self.cfg.device).eval()

    def _observation(self, crop: np.ndarray) -> tuple[np.ndarray, float]:
        return cv2.cvtColor(crop, cv2.COLOR_RGB2GRAY), 1.0

    def _extract(self, images: list[np.ndarray]) -> list[Keypoints]:
        return detect(self._model.keypoint_detector, images, self.cfg.device, self.cfg.max_keypoints)

    def _pair(self, obs: Keypoints, ref: Keypoints) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return tuple(t.cpu().numpy() for t in self._match_pair(obs, ref))
