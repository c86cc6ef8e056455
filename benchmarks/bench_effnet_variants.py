"""effnet with ``torch.compile`` (the matcher's ``compile=True``) against eager: the speed, and the AUROC it costs.

Per config (the default, and ``layer=blocks.3 img_size=224``):
- frames/s of ``matcher.match`` on real-photo frames, eager and compiled interleaved, fastest run of each,
  and the seconds of each one's first prepare + match (compilation);
- the AUROC (target vs rest, target vs same-category look-alike) of the whole frame-set scored
  compiled, and its change from eager. The option is worth offering only when both move by less
  than ``MAX_AUROC_CHANGE``.

Each variant is a matcher config of its own, never a network swapped under another config's id:
``compile`` is left out of the id (like ``device``, it changes scores by float rounding only), so
each variant is scored into its own cache folder. Dynamic int8 quantisation is not measured: torch's
dynamic kernels cover ``nn.Linear`` only, and EfficientNet's trunk is convolutions (docs/performance.md).

``python -m benchmarks.bench_effnet_variants [--quick] [--frameset PATH] [--speed-only]``: PATH is
the frame-set the AUROC is measured on (default: the real-photo set; pass the real look-alike set).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import torch

from benchmarks.bench_effnet import CONFIGS
from benchmarks.framesets import real_photos
from benchmarks.timing import fastest, once
from pin_match import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.labels import frame_labels, scored_frames
from pin_match.evaluation.core.metrics import frame_arrays, ranking_metrics
from pin_match.scoring import RunOptions, score

MAX_AUROC_CHANGE = 0.005
VARIANTS = {"eager": {}, "compile": {"compile": True}}


def auroc_change(frameset: FrameSet | str | Path, overrides: dict | None = None) -> dict:
    """AUROC target vs rest and vs same-category look-alike, eager and compiled, on the whole ``frameset``."""
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    labels = frame_labels(fs)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, variant in VARIANTS.items():
            table = score(fs, create_matcher("effnet", **(overrides or {}), **variant), out=Path(tmp) / name,
                          run=RunOptions(progress=False))
            metrics = ranking_metrics(frame_arrays(scored_frames(labels, table)))
            out[name] = {k: round(metrics[k], 4) for k in ("auroc_target", "auroc_same")}
    change = {k: round(out["compile"][k] - out["eager"][k], 4) for k in out["eager"]}
    return dict(frameset=str(fs.root), eager=out["eager"], compile=out["compile"], change=change,
                within=all(abs(v) < MAX_AUROC_CHANGE for v in change.values()))


def speeds(fs: FrameSet, overrides: dict, n_frames: int, repeats: int) -> tuple[dict[str, float], dict[str, float]]:
    """frames/s of matcher.match per variant, interleaved, fastest of ``repeats`` (compile time excluded), and
    the seconds of each variant's first prepare + match (where compilation happens)."""
    target = fs.target(fs.episodes.iloc[0].target_object_id)
    images = [fs.image(f) for f in fs.frames.frame_id[:n_frames]]
    matchers = {name: create_matcher("effnet", **overrides, **variant) for name, variant in VARIANTS.items()}
    first_call = {name: round(once(lambda m=m: (m.prepare(target), m.match(images[0]))).wall_s, 2)
                  for name, m in matchers.items()}
    best = fastest({name: lambda m=m: [m.match(im) for im in images] for name, m in matchers.items()}, repeats)
    return {name: round(n_frames / t.wall_s, 2) for name, t in best.items()}, first_call


def run(quick: bool = False, frameset: str | Path | None = None, auroc: bool = True) -> dict:
    """``auroc=False`` times the variants only: the AUROC does not depend on the load, the speed does, so the
    AUROC can be measured apart, beside other jobs, and the speed alone on a quiet machine."""
    speed_fs = real_photos()
    auroc_fs = FrameSet.load(frameset) if frameset else speed_fs
    out: dict = {"torch_threads": torch.get_num_threads(), "auroc_frameset": str(auroc_fs.root) if auroc else None}
    configs = dict(list(CONFIGS.items())[:1]) if quick else CONFIGS
    for label, overrides in configs.items():
        fps, first_call = speeds(speed_fs, overrides, 2 if quick else 24, 1 if quick else 6)
        row = out[label] = {"frames_per_s": fps, "first_call_s": first_call}
        print(f"\neffnet {label}: compile {fps['compile']:.2f} frames/s, eager {fps['eager']:.2f} "
              f"({fps['compile'] / fps['eager']:.2f}x); first call {first_call['compile']:.1f} s compiled, "
              f"{first_call['eager']:.1f} s eager", flush=True)
        if auroc:
            a = row["auroc"] = auroc_change(auroc_fs, overrides)
            print(f"AUROC target {a['compile']['auroc_target']:.4f} ({a['change']['auroc_target']:+.4f}), "
                  f"AUROC same {a['compile']['auroc_same']:.4f} ({a['change']['auroc_same']:+.4f}); both move "
                  f"< {MAX_AUROC_CHANGE}: {a['within']}", flush=True)
    return out


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--frameset", help="frame-set for the AUROC change (default: the real-photo set)")
    p.add_argument("--speed-only", action="store_true", help="time the variants, skip the AUROC")
    args = p.parse_args()
    run(quick=args.quick, frameset=args.frameset, auroc=not args.speed_only)
