"""What a close look shows: ``python -m benchmarks.walkup_views FRAMESET [--scores DIR] [--split val]``.

An approach-verify policy walks up to what fired and looks again (``pin_match.data.walkup``); a synthetic set's
walk-ups are rendered and scored on demand into frame-sets of their own under the score cache
(``<scores>/walkups/<fingerprint>/sets``). Over every walk-up view scored so far, per matcher, by how far the object
it shows is (its mean depth in the view): the views that show the episode's target against those that show a
same-family look-alike (AUROC-same, the project's ``metrics.auroc``), and against those that show neither. A view
that shows the target is a view of a walk-up to the target or past it; the analysis reads the masks, the policy
never does.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import outputs
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.metrics import auroc
from pin_match.scoring.cache import read_meta
from pin_match.scoring.walkups import WALKUPS

BANDS = (0.0, 1.0, 1.5, 2.5, 5.0)  # metres: the visible object's mean depth in the view
SHOWN_PX = 200  # an object shows in a view from this many pixels


def view_rows(walkups: FrameSet, split: str) -> pd.DataFrame:
    """Per walk-up frame of ``split``: whether it shows the target, a look-alike (``SHOWN_PX``), and how far."""
    vis = walkups.visibility.reindex(columns=[*walkups.visibility.columns.drop("depth", errors="ignore"), "depth"])
    vis = vis[vis.pixels >= SHOWN_PX]  # a set whose views show no object stores no depth column
    frames = walkups.frames[walkups.frames.split == split][["frame_id"]]
    for role, name in (("target", "target"), ("same_category", "lookalike")):
        shown = vis[vis.role == role].groupby("frame_id").depth.min().rename(f"{name}_depth")
        frames = frames.merge(shown, left_on="frame_id", right_index=True, how="left")
    return frames


def walkup_table(fs: FrameSet, scores: Path, split: str) -> pd.DataFrame:
    rows = []
    for folder in sorted((scores / WALKUPS / fs.fingerprint / "sets").glob("[!.]*")):
        walkups = FrameSet.load(folder)
        views = view_rows(walkups, split)
        for table in scores.glob(f"*/{walkups.fingerprint}/scores_*.parquet"):
            scored = views.merge(pd.read_parquet(table, columns=["frame_id", "score"]), on="frame_id")
            rows.append(scored.assign(matcher=read_meta(table)["matcher_id"]))
    if not rows:
        return pd.DataFrame()
    views = pd.concat(rows, ignore_index=True).drop_duplicates(["matcher", "frame_id"])
    views["depth"] = views[["target_depth", "lookalike_depth"]].min(axis=1)
    views["band"] = pd.cut(views.depth, BANDS)
    out = []
    for (matcher, band), group in views.groupby(["matcher", "band"], observed=True):
        target = group.target_depth.notna() & group.lookalike_depth.isna()
        same = group.lookalike_depth.notna() & group.target_depth.isna()
        out.append(dict(matcher=matcher, band_m=str(band), target_views=int(target.sum()),
                        lookalike_views=int(same.sum()), auroc_same=auroc(group.score[target].to_numpy(np.float64),
                                         group.score[same].to_numpy(np.float64))))
    return pd.DataFrame(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frameset")
    parser.add_argument("--scores", type=Path, default=outputs.SCORES, help="the score cache the walk-ups went to")
    parser.add_argument("--split", default="val")
    a = parser.parse_args()
    table = walkup_table(FrameSet.load(a.frameset), a.scores, a.split)
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3f}"))


if __name__ == "__main__":
    main()
