"""effnet's network variants: dynamic int8 quantisation and ``torch.compile``, speed and the AUROC they cost.

Per variant (fp32 as measured, ``int8-dynamic``, and ``compile``: the matcher's ``compile=True``) and per
config (the default, and ``layer=blocks.3 img_size=224``):
- frames/s of ``matcher.match`` on real-photo frames, variants interleaved, fastest run of each, and the
  seconds of each variant's first prepare + match (compilation);
- the AUROC (target vs rest, target vs same-category look-alike) of the whole frame-set scored
  with the variant, and its change from fp32. An option is worth offering only when both move
  by less than ``MAX_AUROC_CHANGE``.

Dynamic int8 (``torch.ao.quantization.quantize_dynamic``) has kernels for ``nn.Linear`` (and
RNNs) only, not for ``nn.Conv2d``; EfficientNet's trunk is all convolutions, so the benchmark
prints how many modules it quantised (0 expected: the variant is then the fp32 network).

``python -m benchmarks.bench_effnet_variants [--quick] [--frameset PATH] [--speed-only]``: PATH is
the frame-set the AUROC is measured on (default: the real-photo set; pass the real look-alike set).
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time
import warnings
from pathlib import Path

import torch

from benchmarks.bench_effnet import CONFIGS
from benchmarks.framesets import real_photos
from pin_match import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.labels import frame_labels, scored_frames
from pin_match.evaluation.metrics import frame_arrays, ranking_metrics
from pin_match.scoring import score

MAX_AUROC_CHANGE = 0.005


def int8_dynamic(trunk: torch.nn.Module) -> torch.nn.Module:
    with warnings.catch_warnings():  # torch.ao.quantization announces its move to torchao on every call
        warnings.simplefilter("ignore", DeprecationWarning)
        return torch.ao.quantization.quantize_dynamic(copy.deepcopy(trunk), {torch.nn.Linear, torch.nn.Conv2d},
                                                      dtype=torch.qint8)


VARIANTS = ("fp32", "int8-dynamic", "compile")


def quantised_modules(trunk: torch.nn.Module) -> int:
    """How many modules dynamic int8 replaced (those of torch's quantized packages)."""
    return sum(".quantized" in type(m).__module__ for m in int8_dynamic(trunk).modules())


def variant_matcher(variant: str, overrides: dict):
    """An effnet matcher whose network is the variant's: ``compile`` is the matcher's own option, int8 a swapped
    network. Both keep the fp32 matcher's id, so each is scored into its own cache folder."""
    if variant == "compile":
        return create_matcher("effnet", **overrides, compile=True)
    matcher = create_matcher("effnet", **overrides)
    if variant == "int8-dynamic":
        matcher.backbone.trunk = int8_dynamic(matcher.backbone.trunk)
    return matcher


def auroc_change(frameset: FrameSet | str | Path, variant: str, overrides: dict | None = None) -> dict:
    """AUROC target vs rest and vs same-category look-alike, fp32 and ``variant``, on the whole ``frameset``."""
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    labels = frame_labels(fs)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("fp32", variant):
            table = score(fs, variant_matcher(name, overrides or {}), out=Path(tmp) / name, progress=False)
            metrics = ranking_metrics(frame_arrays(scored_frames(labels, table)))
            out[name] = {k: round(metrics[k], 4) for k in ("auroc_target", "auroc_same")}
    change = {k: round(out[variant][k] - out["fp32"][k], 4) for k in out["fp32"]}
    return dict(frameset=str(fs.root), fp32=out["fp32"], variant=out[variant], change=change,
                within=all(abs(v) < MAX_AUROC_CHANGE for v in change.values()))


def speeds(fs: FrameSet, overrides: dict, n_frames: int, repeats: int) -> tuple[dict[str, float], dict[str, float]]:
    """frames/s of matcher.match per variant, interleaved, fastest of ``repeats`` (compile time excluded), and
    the seconds of each variant's first prepare + match (where compilation happens)."""
    episode = fs.episodes.iloc[0]
    images = [fs.image(f) for f in fs.frames.frame_id[:n_frames]]
    matchers, first_call = {}, {}
    for name in VARIANTS:
        matchers[name] = variant_matcher(name, overrides)
        t0 = time.perf_counter()
        matchers[name].prepare(fs.target(episode.target_object_id))
        matchers[name].match(images[0])  # warm-up (and compilation)
        first_call[name] = round(time.perf_counter() - t0, 2)
    best = dict.fromkeys(VARIANTS, float("inf"))
    for _ in range(repeats):
        for name, matcher in matchers.items():
            t0 = time.perf_counter()
            for im in images:
                matcher.match(im)
            best[name] = min(best[name], time.perf_counter() - t0)
    return {name: round(n_frames / s, 2) for name, s in best.items()}, first_call


def run(quick: bool = False, frameset: str | Path | None = None, auroc: bool = True) -> dict:
    """``auroc=False`` times the variants only: the AUROC does not depend on the load, the speed does, so the
    AUROC can be measured apart, beside other jobs, and the speed alone on a quiet machine."""
    speed_fs = real_photos()
    auroc_fs = FrameSet.load(frameset) if frameset else speed_fs
    out: dict = {"torch_threads": torch.get_num_threads(), "auroc_frameset": str(auroc_fs.root) if auroc else None}
    configs = dict(list(CONFIGS.items())[:1]) if quick else CONFIGS
    for label, overrides in configs.items():
        trunk = create_matcher("effnet", **overrides).backbone.trunk
        n_quantised = quantised_modules(trunk)
        fps, first_call = speeds(speed_fs, overrides, 2 if quick else 24, 1 if quick else 6)
        row = out[label] = {"frames_per_s": fps, "first_call_s": first_call,
                            "int8_dynamic_quantised_modules": n_quantised}
        why = " (no Linear in the trunk, no dynamic int8 Conv2d: it is the fp32 network)" if not n_quantised else ""
        print(f"\neffnet {label}: dynamic int8 quantised {n_quantised} modules{why}")
        if not auroc:
            print("  ".join(f"{variant} {fps[variant]:.2f} frames/s ({fps[variant] / fps['fp32']:.2f}x, first call "
                            f"{first_call[variant]:.1f} s)" for variant in VARIANTS), flush=True)
            continue
        print(f"{'variant':<14} {'frames/s':>9} {'speed-up':>9} {'AUROC target':>13} {'change':>8} "
              f"{'AUROC same':>11} {'change':>8}  AUROC moves < {MAX_AUROC_CHANGE}")
        for variant in VARIANTS:
            if variant == "fp32":
                continue
            a = row[variant] = auroc_change(auroc_fs, variant, overrides)
            print(f"{variant:<14} {fps[variant]:>9.2f} {fps[variant] / fps['fp32']:>8.2f}x "
                  f"{a['variant']['auroc_target']:>13.4f} {a['change']['auroc_target']:>+8.4f} "
                  f"{a['variant']['auroc_same']:>11.4f} {a['change']['auroc_same']:>+8.4f}  {a['within']}", flush=True)
        print(f"{'fp32':<14} {fps['fp32']:>9.2f} {1:>8.2f}x {a['fp32']['auroc_target']:>13.4f} {'':>8} "
              f"{a['fp32']['auroc_same']:>11.4f}")
    return out


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--frameset", help="frame-set for the AUROC change (default: the real-photo set)")
    p.add_argument("--speed-only", action="store_true", help="time the variants, skip the AUROC")
    args = p.parse_args()
    run(quick=args.quick, frameset=args.frameset, auroc=not args.speed_only)
