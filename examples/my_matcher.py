"""A complete matcher in one file, to copy. See docs/adding-a-matcher.md.

    cp examples/my_matcher.py my_package/my_matcher.py

then rename the class and the registry name, fill in ``_prepare`` and ``_match_crops`` and
register it: either import the module before ``create_matcher("my-matcher")``, or declare
an entry point so pin_match finds it on its own::

    [project.entry-points."pin_match.matchers"]
    my-matcher = "my_package.my_matcher:MyMatcher"

This example is a working matcher: the mean colour of the target against the mean colour
of image patches, registered under "example-mean-color" when the file is imported. It
lives outside the built-in package, so ``pin-match list`` never shows it;
tests/test_docs_examples.py loads it as a plug-in through an entry point. Test yours with
``pin_match.contract.check_matcher("my-matcher")``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pin_match.contract import CropConfig, CropMatcher, MatchResult, Modality, Target, register_matcher


@dataclass
class MeanColorConfig(CropConfig):
    """Every field can be set with ``--cfg key=value``; it changes the config hash (cache key)."""

    grid: int = 8  # patches per crop side


@register_matcher("example-mean-color")
class MeanColorMatcher(CropMatcher):
    """Why this matcher exists (say it here): a minimal, complete example of the interface."""

    Config = MeanColorConfig
    modality = Modality.VISUAL     # VISUAL: reference views; TEXTUAL: descriptions; CATEGORY: may read the label
    default_sigma = 0.9            # the threshold a user should start from (never applied here)
    paper = ""
    version = 1                    # bump when a change alters results, so old caches are not reused

    def _prepare(self, target: Target) -> None:
        # Runs once per target. Load weights lazily here (never in __init__ or at import).
        pixels = np.concatenate([v[..., :3][v[..., 3] > 127] for v in target.views]).astype(np.float32)
        self._color = pixels.mean(0) / 255.0

    def _match_crops(self, crops: list[np.ndarray]) -> list[MatchResult]:
        # Receives every crop of a batch (PIN's two square crops per frame by default);
        # return one result per crop in crop pixel coordinates. Do NOT threshold: return
        # all candidate points with their scores; points_at(sigma) filters later.
        out = []
        g = self.cfg.grid
        for crop in crops:
            h, w = crop.shape[:2]
            cells = cv2.resize(crop, (g, g), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
            similarity = 1.0 - np.linalg.norm(cells - self._color, axis=2) / np.sqrt(3.0)
            ys, xs = np.mgrid[:g, :g]
            points = np.stack([(xs.ravel() + 0.5) * w / g, (ys.ravel() + 0.5) * h / g], axis=1)
            out.append(MatchResult(score=float(similarity.max()), points=points,
                                   point_scores=similarity.ravel(), heatmap=similarity))
        return out
