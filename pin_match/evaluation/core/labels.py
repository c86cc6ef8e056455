"""Per-frame ground truth for the detection metrics, derived from a frame-set's visibility table.

The metrics only need a handful of facts per frame (is the target, a same-category or an
other-category distractor visible; is the target "seen" by PIN's stricter rule), so they
are computed once here and the metric functions stay pure functions of small tables.
Only localisation needs pixels, and it reads masks for matched target frames alone.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.scoring.table import ScoreTable, points_at, require_finite

SEEN_MIN_FRACTION = 0.05  # PIN: the target covers more than 5 % of the frame ...
SEEN_MAX_DEPTH_M = 5.0    # ... and its mean depth is below 5 m

CLASSES = ("TM", "CM", "GM", "OM")  # frame class codes 0..3, in PIN's order of precedence
TM, CM, GM, OM = range(4)
FIT_CLASSES = {"target": (TM,), "same_category": (CM,), "other": (GM, OM)}  # what a fit weighs equally
UNUSED = -1  # a row a fit leaves out (``class_weights`` gives it no weight)

LABEL_COLUMNS = ["frame_id", "episode_id", "step", "split", "target_category", "target_visible", "same_visible",
                 "other_visible", "target_pixels", "target_depth", "target_seen", "approach"]


class LabelError(PinMatchError, ValueError):
    """Scores and ground truth do not fit together."""


def frame_labels(fs: FrameSet) -> pd.DataFrame:
    """One row per frame of ``fs`` with the visibility facts the metrics classify by.

    ``target_seen`` is 1.0 / 0.0, or NaN where the rule cannot be decided (the target is
    large enough but the frame-set has no depth for it). ``approach``: the frame is an approach view (what an agent
    sees walking up to an object to check it), which no metric of the walk reads (``scored_frames``).
    """
    frames, vis = fs.frames, fs.visibility
    out = frames[["frame_id", "episode_id", "step", "split"]].copy()
    category = dict(zip(fs.episodes.episode_id, fs.episodes.target_category))
    out["target_category"] = out.episode_id.map(category)
    for role, column in (("target", "target_visible"), ("same_category", "same_visible"), ("other", "other_visible")):
        out[column] = out.frame_id.isin(vis.frame_id[vis.role == role])

    target = vis[vis.role == "target"]
    depth = target["depth"] if "depth" in target.columns else pd.Series(np.nan, index=target.index)
    agg = pd.DataFrame({"frame_id": target.frame_id, "pixels": target.pixels.astype(float),
                        "depth_x_pixels": depth.astype(float) * target.pixels}).groupby("frame_id").sum(min_count=1)
    pixels = out.frame_id.map(agg["pixels"]).fillna(0.0).to_numpy(float)
    mean_depth = out.frame_id.map(agg["depth_x_pixels"] / agg["pixels"]).to_numpy(float)
    area = (frames["height"] * frames["width"]).to_numpy(float) if {"height", "width"} <= set(frames.columns) \
        else np.full(len(frames), np.nan)
    out["target_pixels"] = pixels.astype(np.int64)
    out["target_depth"] = mean_depth
    out["target_seen"] = seen_rule(pixels, area, mean_depth)
    out["approach"] = frames.frame_id.isin(fs.approach_views.frame_id).to_numpy()
    return out[LABEL_COLUMNS]


def frame_classes(labels: pd.DataFrame) -> np.ndarray:
    """Each frame's class code (int8) by PIN's precedence: the target visible (TM), else a same-category
    look-alike (CM), else another object (GM), else nothing (OM)."""
    target, same, other = (labels[c].to_numpy(bool) for c in ("target_visible", "same_visible", "other_visible"))
    return np.where(target, TM, np.where(same, CM, np.where(other, GM, OM))).astype(np.int8)


def class_weights(classes: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    """Sample weights that give each of ``FIT_CLASSES`` the same total (1), and the rows per class.

    The fits weigh target, same-category look-alike and other rows alike, so the few look-alike
    frames that matter most are not drowned by empty rooms. A row of class ``UNUSED`` weighs 0;
    an empty class adds nothing.
    """
    weights = np.zeros(len(classes))
    counts = {}
    for name, codes in FIT_CLASSES.items():
        mask = np.isin(classes, codes)
        counts[name] = int(mask.sum())
        if counts[name]:
            weights[mask] = 1.0 / counts[name]
    return weights, counts


def seen_rule(pixels: np.ndarray, area: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """PIN's "seen": both conditions true -> 1, either false -> 0, otherwise undecidable -> NaN."""
    with np.errstate(invalid="ignore"):
        big = np.where(np.isnan(area), np.nan, (pixels > SEEN_MIN_FRACTION * area).astype(float))
        near = np.where(np.isnan(depth), np.nan, (depth < SEEN_MAX_DEPTH_M).astype(float))
    false = (big == 0) | (near == 0)
    return np.where(false, 0.0, np.where(np.isnan(big) | np.isnan(near), np.nan, 1.0))


def scored_frames(labels: pd.DataFrame, table: ScoreTable, approach: bool = False) -> pd.DataFrame:
    """Labels of the walk's frames the table scored, with their score; the table defines the scope. ``approach``:
    the approach views instead, which only an approach-verify policy reads (``stop.ApproachVerify``).

    A scored frame the labels do not know means the scores belong to another frame-set,
    and a non-finite score would silently count as unmatched: both are errors naming the frame.
    """
    scores = table.frames[["frame_id", "score"]]
    unknown = scores.frame_id[~scores.frame_id.isin(labels.frame_id)]
    if len(unknown):
        raise LabelError(f"score table of {table.matcher_id} has frame {unknown.iloc[0]!r}, which the frame-set "
                         f"does not contain (scored on another frame-set?)")
    require_finite(scores.frame_id, scores.score, f"score table of {table.matcher_id}", LabelError)
    scored = labels.merge(scores, on="frame_id", how="inner", validate="one_to_one")
    return scored[scored["approach"] == approach].reset_index(drop=True)


def localisation_hits(fs: FrameSet, table: ScoreTable, sigma: float) -> pd.DataFrame:
    """For every matched frame showing the target: how many of its points fall on target pixels.

    A point (x, y) in frame pixels is on the target when the instance mask at
    (floor(y), floor(x)) carries one of the target's mask values.
    """
    vis = fs.visibility[fs.visibility.role == "target"]
    target_values = vis.groupby("frame_id").mask_value.apply(lambda v: np.asarray(v, np.int64))
    rows = table.frames[(table.frames.score >= sigma) & table.frames.frame_id.isin(target_values.index)]
    out = []
    for _, row in rows.iterrows():
        points = points_at(row, sigma)
        mask = fs.instance_mask(row.frame_id)
        xs = np.clip(np.floor(points[:, 0]).astype(np.int64), 0, mask.shape[1] - 1)
        ys = np.clip(np.floor(points[:, 1]).astype(np.int64), 0, mask.shape[0] - 1)
        on = int(np.isin(mask[ys, xs], target_values[row.frame_id]).sum())
        out.append(dict(frame_id=row.frame_id, n_points=len(points), n_on_target=on, hit=on > 0))
    return pd.DataFrame(out, columns=["frame_id", "n_points", "n_on_target", "hit"])
