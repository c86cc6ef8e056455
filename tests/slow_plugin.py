"""A deliberately slow matcher for the kill/resume and concurrency tests (imported by subprocesses)."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

from pin_match import CropConfig, CropMatcher, MatchResult, Modality, register_matcher


@dataclass
class SlowConfig(CropConfig):
    delay: float = 0.2


@register_matcher("test-slow")
class SlowMatcher(CropMatcher):
    """Score = mean brightness of the crop; sleeps so a run can be killed half way."""

    Config = SlowConfig
    modality = Modality.VISUAL
    default_sigma = 100.0

    def _prepare(self, target):
        log = os.environ.get("PIN_MATCH_TEST_LOG")
        if log:
            with open(log, "a") as fh:
                fh.write(f"{os.getpid()} prepare {target.object_id}\n")

    def _match_crops(self, crops):
        time.sleep(self.cfg.delay * len(crops) / 2)
        return [MatchResult(score=float(c.mean()), points=[[c.shape[1] / 2, c.shape[0] / 2]]) for c in crops]
