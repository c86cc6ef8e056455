"""The toy matchers and the fake PIN recording the tests share.

The toys are real plug-ins (registered, validated and cached like any matcher) whose scores
are image statistics, so a test of scoring, the cluster or the command line runs no model.
Subprocesses and Dask workers find them by importing this module (``tests/`` on their path).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pin_match import CropConfig, CropMatcher, Matcher, MatcherConfig, MatchResult, Modality, register_matcher


@dataclass
class SlowConfig(CropConfig):
    delay: float = 0.2  # seconds per frame (two crops)


@register_matcher("test-slow")
class SlowMatcher(CropMatcher):
    """Score = mean brightness of the crop, one point at its centre; sleeps so a run can be killed half way."""

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


@dataclass
class NanConfig(SlowConfig):
    bad_target: str = ""
    value: float = float("nan")


@register_matcher("test-nan-for")
class NanForTarget(SlowMatcher):
    """test-slow, but every score is ``value`` (NaN unless set) while prepared for ``bad_target``: a matcher error in
    that target's episodes only."""

    Config = NanConfig

    def _prepare(self, target):
        self.bad = target.object_id == self.cfg.bad_target

    def _match_crops(self, crops):
        results = super()._match_crops(crops)
        for r in results:
            r.score = self.cfg.value if self.bad else r.score
        return results


@dataclass
class BrightConfig(MatcherConfig):
    gain: float = 1.0
    channels: tuple[int, ...] = (0, 1, 2)
    verbose: bool = False


@register_matcher("test-bright")
class BrightMatcher(Matcher):
    """A whole-frame matcher: scores an image by its brightest pixel (times ``gain``); the point is that pixel."""

    Config = BrightConfig
    modality = Modality.VISUAL
    default_sigma = 100.0

    def _prepare(self, target):
        self.prepared_with = target

    def _match_batch(self, images):
        out = []
        for im in images:
            lum = im[..., list(self.cfg.channels)].astype(float).mean(-1) * self.cfg.gain
            y, x = np.unravel_index(np.argmax(lum), lum.shape)
            out.append(MatchResult(score=float(lum.max()), points=[[x, y]]))
        return out


class HandSet(Matcher):
    """Not registered: returns the result it is given for every image, and the embedding given for each reference
    view (found by the view's bytes)."""

    name = "hand-set"

    def __init__(self, result: MatchResult | None = None, embeddings: dict[bytes, list[float]] | None = None) -> None:
        super().__init__()
        self.result, self.embeddings = result, embeddings or {}

    def _prepare(self, target) -> None:
        pass

    def _match_batch(self, images):
        return [self.result for _ in images]

    def embed_reference(self, view: np.ndarray) -> np.ndarray:
        return np.asarray(self.embeddings[view.tobytes()])


OBJECTS = (("obj_t", (200, 20, 20)), ("obj_s", (20, 200, 20)), ("obj_o", (20, 20, 200)))  # target, look-alike, other


def write_recording(root: Path, steps: int = 3, shape: tuple[int, int] = (64, 48), view_size: int = 96) \
        -> tuple[Path, Path, list[tuple[np.ndarray, np.ndarray]]]:
    """A PIN recording of one episode (``root/rec``) and its objects folder (``root/objects``), the layout of
    docs/frameset.md: random RGB, PIN's semantic labels (plus an unknown label 5) and depth per step, the target
    absent from step 2. Returns both folders and each step's (semantic, depth)."""
    import cv2

    from conftest import make_view

    rng = np.random.default_rng(0)
    objects = root / "objects"
    descriptions = {}
    for oid, color in OBJECTS:
        folder = objects / "objects_images" / oid
        folder.mkdir(parents=True)
        for k in range(3):
            cv2.imwrite(str(folder / f"{oid}_{k}.png"), cv2.cvtColor(make_view(color, view_size), cv2.COLOR_RGBA2BGRA))
        descriptions[oid] = [f"{oid} description {k}" for k in range(3)]
    (objects / "objects_descriptions.json").write_text(json.dumps(descriptions))
    rec = root / "rec"
    rec.mkdir()
    episodes = [dict(episode_id="7", scene_id="sceneA",
                     goals=[dict(object_id="obj_t", object_category="mug")],
                     distractors=[dict(object_id="obj_s", object_category="mug"),
                                  dict(object_id="obj_o", object_category="ball")])]
    (rec / "episodes.json").write_text(json.dumps({"episodes": episodes}))
    semantics = []
    for step in range(steps):
        for sub in ("rgb", "semantic", "depth"):
            (rec / "7" / sub).mkdir(parents=True, exist_ok=True)
        rgb = rng.integers(0, 255, (*shape, 3), dtype=np.uint8)
        sem = rng.choice([0, 5, 100000, 100001, 100002], size=shape).astype(np.int64)
        if step == 2:
            sem[sem == 100000] = 0  # a frame without the target
        depth = rng.uniform(0.5, 5.0, shape).astype(np.float32)
        cv2.imwrite(str(rec / "7" / "rgb" / f"{step}.png"), rgb)
        np.save(rec / "7" / "semantic" / f"{step}.npy", sem)
        np.save(rec / "7" / "depth" / f"{step}.npy", depth)
        semantics.append((sem, depth))
    return rec, objects, semantics
