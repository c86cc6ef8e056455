"""What a close look changes: ``python -m benchmarks.approach_views FRAMESET TABLE [--split val]``.

Over a frame-set's approach views (docs/frameset.md) and one matcher's score table, by the view's
distance to the object it walks up to: the median score of views of the episode's target, of a
same-family look-alike and of another object, and the AUROC of target views against look-alike views
(AUROC-same) and against other objects' views. An approach-verify policy commits on these views, so
this is how well its second look can tell the target from what fired on the way.
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd

from pin_match.data.frameset import FrameSet

BANDS = (0.0, 0.75, 1.25, 3.0)  # metres, horizontal: the generator's views stand 1.0, 0.5 and 0 m of walk short


def auroc(positive: np.ndarray, negative: np.ndarray) -> float:
    """P(a positive scores above a negative), ties counting half."""
    if not len(positive) or not len(negative):
        return float("nan")
    above = (positive[:, None] > negative[None]).mean() + 0.5 * (positive[:, None] == negative[None]).mean()
    return float(above)


def close_look_table(fs: FrameSet, scores: pd.DataFrame, split: str) -> pd.DataFrame:
    views = fs.approach_views.merge(scores[["frame_id", "score"]], on="frame_id")
    views = views.merge(fs.episodes[["episode_id", "target_object_id", "target_category"]], on="episode_id")
    views = views[views.split == split]
    category = dict(zip(fs.objects.object_id, fs.objects.category))
    views = views.assign(role=np.where(views.approach_of == views.target_object_id, "target",
                                       np.where(views.approach_of.map(category) == views.target_category,
                                                "look-alike", "other")),
                         band=pd.cut(views.approach_distance, BANDS))
    rows = []
    for band, group in views.groupby("band", observed=True):
        by_role = {role: group.score[group.role == role].to_numpy(np.float64)
                   for role in ("target", "look-alike", "other")}
        rows.append(dict(band_m=str(band), views=len(group),
                         **{f"median_{role}": float(np.median(s)) if len(s) else np.nan for role, s in by_role.items()},
                         auroc_same=auroc(by_role["target"], by_role["look-alike"]),
                         auroc_other=auroc(by_role["target"], by_role["other"])))
    return pd.DataFrame(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frameset")
    parser.add_argument("table", help="a score table (scores_all.parquet) of the frame-set")
    parser.add_argument("--split", default="val")
    a = parser.parse_args()
    table = close_look_table(FrameSet.load(a.frameset), pd.read_parquet(a.table, columns=["frame_id", "score"]),
                             a.split)
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3f}"))


if __name__ == "__main__":
    main()
