"""Whole scoring runs against the matcher's own work and against its bare network, on the same episodes.

Figures (docs/performance.md, section "Where a matcher's seconds go"): for ``effnet`` and ``verify``
on the val episodes of two frame-sets (the real look-alikes, ``pin-match data build core50 OUT
--variant approach``, and a small default synthetic set, ``pin-match synth``), three sides timed
side by side, interleaved, the fastest of the repeats:

- **score run**: ``scoring.score`` into a fresh cache, the whole engine (decoding, a prepare per
  episode, batches of ``RunOptions.batch_size`` frames, writing the table), as ``pin-match score``;
- **own**: the matcher's own ``prepare`` per episode and ``match_batch`` on the same batches of the
  same frames, decoded before the clock;
- **bare network**: the network's forward passes (``FeatureMapBackbone.feature_map``) on exactly the
  inputs the own side gave it, recorded once and replayed: the reference views, the frames' crops
  and, for ``verify``, its candidates' crops; resizing and normalising happen before the clock.

Each matcher's weights are loaded before any clock. Targets (issue 50): score run at most 1.25x own
and at most 1.5x bare.

``python -m benchmarks.bench_network_share [--quick]``.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from benchmarks.framesets import CACHE, cached, synthetic
from benchmarks.loadavg import load_1min
from benchmarks.timing import Timing, fastest
from pin_match import create_matcher
from pin_match.contract import Matcher, Target
from pin_match.data.frameset import FrameSet
from pin_match.matchers.common.backbones import FeatureMapBackbone
from pin_match.matchers.common.patch import PatchSimilarityMatcher
from pin_match.scoring import RunOptions, score

MATCHERS = ("effnet", "verify")
RUN = RunOptions(progress=False)
OWN_RATIO, BARE_RATIO = 1.25, 1.5


def real_lookalikes() -> FrameSet:
    """The demo's real set: CORe50 look-alikes as approaching walks (``pin-match data build core50 --variant
    approach``), cached."""
    from pin_match.data.sources.catalogue import get

    return cached(CACHE / "core50_approach", lambda root: get("core50").build(root, "approach", overwrite=True))


def val_episodes(fs: FrameSet, n: int | None) -> FrameSet:
    """The val split, cut to its first ``n`` episodes (all when None)."""
    part = fs.split("val")
    if n is not None:
        keep = set(part.episodes.episode_id[:n])
        part.episodes = part.episodes[part.episodes.episode_id.isin(keep)].reset_index(drop=True)
        part.frames = part.frames[part.frames.episode_id.isin(keep)].reset_index(drop=True)
    return part


@dataclass
class Episode:
    target_id: str
    batches: list[list[np.ndarray]]


def decoded(fs: FrameSet) -> list[Episode]:
    """Every episode's frames, decoded, in the engine's batches (step order, ``RUN.batch_size`` frames)."""
    out = []
    for ep in fs.episodes.itertuples():
        frames = fs.frames[fs.frames.episode_id == ep.episode_id].sort_values("step")
        images = [fs.image(f) for f in frames.frame_id]
        out.append(Episode(ep.target_object_id,
                           [images[i:i + RUN.batch_size] for i in range(0, len(images), RUN.batch_size)]))
    return out


def backbones(matcher: Matcher) -> list[FeatureMapBackbone]:
    """The feature-map networks a matcher runs: its own, or its parts' (``verify``: locate and zoom)."""
    patchy = [matcher, *matcher.parts().values()]
    return [m.backbone for m in patchy if isinstance(m, PatchSimilarityMatcher)
            and isinstance(m.backbone, FeatureMapBackbone)]


@dataclass
class Own:
    """The matcher's own side: ``prepare`` when an episode's target differs from the last one's (as the engine does),
    then ``match_batch`` on each batch; ``record`` keeps what it fed each network, by phase."""

    matcher: Matcher
    episodes: list[Episode]
    targets: dict[str, Target]
    passes: dict[str, list[tuple[FeatureMapBackbone, torch.Tensor]]] = field(default_factory=dict)
    phase: str = ""

    def __call__(self) -> None:
        held = None
        for ep in self.episodes:
            if ep.target_id != held:
                self.phase = "references"
                self.matcher.prepare(self.targets[ep.target_id])
                held = ep.target_id
            self.phase = "frames"
            for batch in ep.batches:
                self.matcher.match_batch(batch)

    def record(self) -> None:
        """One run with every network's ``feature_map`` input kept (a clone), by phase and input size."""
        nets = backbones(self.matcher)
        for bb in nets:
            bb.feature_map = self._recorder(bb, bb.feature_map)
        try:
            self()
        finally:
            for bb in nets:
                del bb.feature_map  # the class's method again

    def _recorder(self, bb: FeatureMapBackbone, forward: Callable) -> Callable:
        def recorded(x: torch.Tensor) -> torch.Tensor:
            self.passes.setdefault(f"{self.phase} at {bb.input_size} px", []).append((bb, x.clone()))
            return forward(x)
        return recorded


def bare_side(passes: list[tuple[FeatureMapBackbone, torch.Tensor]]) -> Callable[[], None]:
    return lambda: [bb.feature_map(x) for bb, x in passes]


def compare(fs: FrameSet, name: str, repeats: int) -> dict:
    """The three sides for one matcher on one frame-set; the network's passes split by phase."""
    matcher = create_matcher(name)
    episodes = decoded(fs)
    own = Own(matcher, episodes, {ep.target_id: fs.target(ep.target_id) for ep in episodes})
    own.record()  # also the warm-up: the networks are built (weights loaded) on their first pass

    def score_run() -> None:
        with tempfile.TemporaryDirectory() as tmp:
            score(fs, matcher, out=tmp, run=RUN)

    sides: dict[str, Callable[[], object]] = {"score run": score_run, "own": own}
    sides.update({f"bare: {phase}": bare_side(passes) for phase, passes in own.passes.items()})
    load = {"before": load_1min()}
    best = fastest(sides, repeats)
    load["after"] = load_1min()
    n = len(fs.frames)
    bare = Timing(sum(t.wall_s for k, t in best.items() if k.startswith("bare")),
                  sum(t.cpu_s for k, t in best.items() if k.startswith("bare")))
    best["bare network"] = bare
    row = {side: dict(s_per_frame=round(t.wall_s / n, 4), cpu_s_per_frame=round(t.cpu_s / n, 4))
           for side, t in best.items()}
    row.update(frames=n, episodes=len(episodes), load_1min=load, torch_threads=torch.get_num_threads(),
               score_over_own=round(best["score run"].wall_s / best["own"].wall_s, 3),
               score_over_bare=round(best["score run"].wall_s / bare.wall_s, 3),
               own_over_bare=round(best["own"].wall_s / bare.wall_s, 3),
               passes={phase: len(p) for phase, p in own.passes.items()})
    return row


def report(label: str, name: str, row: dict) -> None:
    load = row["load_1min"]
    print(f"\n{name} on {label}: {row['frames']} frames, {row['episodes']} episodes "
          f"(load {load['before']:.2f} before / {load['after']:.2f} after)")
    print(f"  {'side':<28} {'s/frame':>8} {'CPU s/frame':>12}")
    for side, t in row.items():
        if isinstance(t, dict) and "s_per_frame" in t:
            print(f"  {side:<28} {t['s_per_frame']:8.3f} {t['cpu_s_per_frame']:12.3f}")
    print(f"  score run / own {row['score_over_own']:.2f} (target <= {OWN_RATIO:g}), score run / bare network "
          f"{row['score_over_bare']:.2f} (target <= {BARE_RATIO:g}), own / bare network {row['own_over_bare']:.2f}")


def run(quick: bool = False) -> dict:
    sets = {"real look-alikes (core50 approach, val)": val_episodes(real_lookalikes(), 1 if quick else None),
            "synthetic (pin-match synth, 4 episodes, val)": val_episodes(
                synthetic("synth_pipeline", seed=0, episodes=4), 1 if quick else None)}
    out: dict = {"cpus": os.cpu_count()}
    print("whole score runs against the matcher's own prepare + match_batch and its bare network, same frames, "
          f"fastest of interleaved runs (targets: score / own <= {OWN_RATIO:g}, score / bare <= {BARE_RATIO:g})")
    for label, fs in sets.items():
        for name in MATCHERS:
            row = out[f"{label}: {name}"] = compare(fs, name, 1 if quick else 3)
            report(label, name, row)
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
