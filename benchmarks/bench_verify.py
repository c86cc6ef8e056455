"""verify against the default effnet: the cost per frame of locating, zooming and re-identifying, side by side.

Figures (docs/performance.md): seconds per frame of ``matcher.match`` on real-photo frames
(640x360, one episode's target prepared once) for the default ``effnet``, the default
``verify``, ``verify`` with its keypoint signal on (``xfeat`` on every candidate), ``verify`` read against
the shipped cohort (``cohort-norm``: its cohort scored at ``prepare``, whose seconds are printed
too), the carried ``fusion`` (three EfficientNet passes and ``color``) and ``color``,
interleaved, the fastest of the repeats; each as a multiple of ``effnet``. Targets: verify at most 2x; the
cohort step at most 1.2x verify a frame.

``python -m benchmarks.bench_verify [--quick]``.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.framesets import real_photos
from benchmarks.timing import fastest
from pin_match import create_matcher
from pin_match.fitting.verifier import fit_verifier
from pin_match.matchers.common.verifier_file import SIGNALS

TARGET_RATIO = 2.0
COHORT_RATIO = 1.2  # the cohort step's budget on verify's time a frame (issue 44)


def keypoints_file(fs, folder: Path) -> str:
    """A verifier file for all signals, keypoints included, fitted on the real-photo set: only its cost is read."""
    path = folder / "verify_keypoints.json"
    if not path.exists():
        fit_verifier([fs], path, split="val", overrides={"signals": SIGNALS}, out=folder)
    return str(path)


def run(quick: bool = False) -> dict:
    fs = real_photos()
    folder = fs.root.parent / "verify_bench"
    matchers = {"effnet": create_matcher("effnet"), "verify": create_matcher("verify"),
                "verify with keypoints": create_matcher("verify", signals=SIGNALS, weights=keypoints_file(fs, folder)),
                "verify, cohort-normalised": create_matcher("cohort-norm"),
                "fusion": create_matcher("fusion"), "color": create_matcher("color")}
    episode = fs.episodes.iloc[0]
    target = fs.target(episode.target_object_id)
    images = [fs.image(f) for f in fs.frames.frame_id[fs.frames.episode_id == episode.episode_id]]
    n = 3 if quick else len(images)
    prepare_s = {}
    for name, matcher in matchers.items():
        prepare_s[name] = fastest({name: lambda m=matcher: m.prepare(target)})[name].wall_s
        matcher.match(images[0])  # warm-up: weights loaded, first-call allocations done
    sides = {name: (lambda m=m: [m.match(im) for im in images[:n]]) for name, m in matchers.items()}
    best = fastest(sides, 1 if quick else 3)
    out = {name: dict(s_per_frame=round(t.wall_s / n, 4), cpu_s_per_frame=round(t.cpu_s / n, 4))
           for name, t in best.items()}
    base = best["effnet"].wall_s
    print(f"matcher.match per frame, {n} real-photo frames, fastest of interleaved runs (target verify / effnet "
          f"<= {TARGET_RATIO:g}):")
    print(f"{'matcher':<26} {'s/frame':>8} {'CPU s/frame':>12} {'x effnet':>9} {'prepare s':>10}")
    for name, t in best.items():
        out[name].update(x_effnet=round(t.wall_s / base, 3), prepare_s=round(prepare_s[name], 2))
        print(f"{name:<26} {t.wall_s / n:8.3f} {t.cpu_s / n:12.3f} {t.wall_s / base:9.2f} {prepare_s[name]:10.2f}")
    out["target_holds"] = out["verify"]["x_effnet"] <= TARGET_RATIO
    cohort, verify = out["verify, cohort-normalised"]["s_per_frame"], out["verify"]["s_per_frame"]
    out["cohort_step_holds"] = cohort <= COHORT_RATIO * verify
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv)
