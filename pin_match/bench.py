"""Side-by-side benchmark: score (cached), tune on train, report on val, one table for all matchers.

This is the toolkit's main job and what ``pin-match demo`` runs on the synthetic default.
Sigma is always chosen on the train split and applied to val, never tuned on val.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from pin_match import atomic
from pin_match.frameset import FrameSet
from pin_match.labels import frame_labels
from pin_match.report import latex_table, markdown_table, report, side_by_side
from pin_match.scoring import score
from pin_match.tuning import DEFAULT_OBJECTIVE, TuningError, tune, write_thresholds

OFFLINE_MATCHERS = ("sift", "color")
DEMO_OUT = Path("pin_match_runs") / "demo"


def bench(frameset: FrameSet | str | Path, matchers: Sequence[str], out: str | Path, *,
          objective: str = DEFAULT_OBJECTIVE, overrides: dict[str, dict] | None = None,
          batch_size: int = 8, workers: int | None = None, n_boot: int = 1000,
          progress: bool = True) -> tuple[pd.DataFrame, list[dict]]:
    """Run every matcher through score -> tune (train) -> report (val); write the joint tables under ``out``."""
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    out = Path(out)
    labels = frame_labels(fs)
    results = []
    for name in matchers:
        table = score(fs, name, overrides=(overrides or {}).get(name), out=out / "scores", batch_size=batch_size,
                      workers=workers, progress=progress)
        try:
            tuned = tune(table, labels, objective=objective, split="train")
            write_thresholds(tuned, out / "thresholds" / f"{name}.json")
            sigma, source = tuned["sigma"], f"tuned on train ({objective})"
        except TuningError as exc:  # e.g. a val-only recording: fall back to the matcher's default, and say so
            sigma, source = table.meta["default_sigma"], f"matcher default ({exc})"
        result = report(table, fs, out / "reports" / name, sigma=sigma, split="val", n_boot=n_boot,
                        sigma_source=source)
        results.append(result)
    joint = side_by_side(results)
    atomic.write_text(out / "table.md", markdown_table(joint) + "\n")
    atomic.write_text(out / "table.tex", latex_table(joint, caption="Detection on the val split; sigma tuned on "
                                                                     "train.") + "\n")
    atomic.write_text(out / "table.csv", joint.to_csv())
    return joint, results


def demo(out: str | Path = DEMO_OUT, matchers: Sequence[str] = OFFLINE_MATCHERS, *, seed: int = 0,
         workers: int | None = None, progress: bool = True) -> tuple[pd.DataFrame, Path]:
    """Generate the default synthetic frame-set if absent, then bench the offline matchers on it."""
    from pin_match.synth import generate

    out = Path(out)
    fs_path = out / "frameset"
    fs = FrameSet.load(fs_path) if (fs_path / "frameset.json").exists() else \
        generate(fs_path, seed=seed, workers=workers)
    joint, _ = bench(fs, matchers, out, workers=workers, progress=progress)
    return joint, out
