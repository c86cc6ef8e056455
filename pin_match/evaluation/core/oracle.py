"""Scores from the ground truth: what a perfect detector would give, the ceiling a walk sets for every matcher.

A frame scores the share of it that the largest object of a role covers (the target, a look-alike), its one point
that object's pixel nearest the object's centroid. Under PIN's first match at sigma = pixels / frame area the agent
stops at the first frame showing the object that large: the oracle's SR is what the walks let any matcher reach.
Analyses and tests read it; no policy or matcher does.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.scoring.table import ScoreTable


def oracle_table(fs: FrameSet, role: str) -> ScoreTable:
    """Every frame of ``fs`` scored by how much of it the largest object of ``role`` covers (0 where none shows)."""
    vis = fs.visibility[fs.visibility.role == role].sort_values("pixels", ascending=False)
    vis = vis.drop_duplicates("frame_id").set_index("frame_id")
    rows = []
    for f in fs.frames.itertuples():
        score, xs, ys = 0.0, [], []
        if f.frame_id in vis.index:
            row = vis.loc[f.frame_id]
            py, px = np.nonzero(fs.instance_mask(f.frame_id) == row.mask_value)
            k = int(np.argmin((px - px.mean()) ** 2 + (py - py.mean()) ** 2))
            score, xs, ys = float(row.pixels) / (f.height * f.width), [px[k] + 0.5], [py[k] + 0.5]
        rows.append(dict(frame_id=f.frame_id, episode_id=f.episode_id, step=f.step, split=f.split, score=score,
                         crop_scores=[score], points_x=xs, points_y=ys, point_scores=[score] * len(xs), view=-1))
    return ScoreTable(pd.DataFrame(rows), dict(matcher=f"oracle-{role}", matcher_id=f"oracle-{role}@0",
                                               frameset_fingerprint=fs.fingerprint))
