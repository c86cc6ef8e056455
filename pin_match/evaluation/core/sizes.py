"""Every ranking figure by the size of what a frame shows: bands of the objects' pixel area, and where the best point
lands.

A PIN agent meets its target across a room first, as a few hundred pixels, and beside it last;
a pooled AUROC mixes both, so a matcher that only finds large objects can look fair on a set of
mostly large ones. Here each frame has the pixel area of the object that decides its class, by
PIN's precedence (``labels.frame_classes``): the target's in a target frame, the largest
same-category look-alike's in a look-alike frame, the largest other object's in a frame showing
only others; a frame showing nothing has none and enters the pooled row only. Every figure of
``size_table`` is then computed per band of that area (``BANDS``), from the same counts as the
pooled metrics (``metrics``), so its "all" row is the report's own. Localisation here is the share
of target frames whose best point (the highest-scoring candidate, whatever sigma) lies on the
target: where the matcher looks, matched or not. Pure functions: tables in, numbers out; the
masks come from the caller (``mask_of``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np
import pandas as pd

from pin_match.evaluation.core.intervals import episode_weights, percentile_interval, unit_codes, weighted_auroc
from pin_match.evaluation.core.labels import CM, GM, TM, frame_classes
from pin_match.evaluation.core.metrics import DEFAULT_BOOT, Bootstrap, auroc
from pin_match.evaluation.core.paired import align

BAND_EDGES = (1000, 2000, 5000)  # pixels: a band holds areas from its lower edge up to, not including, the next
BANDS = ("< 1,000", "1,000-2,000", "2,000-5,000", ">= 5,000")
ALL = "all"
NO_OBJECT = -1  # the band of a frame that shows no object
SIZE_COLUMNS = ("n_target", "n_same", "auroc_same", "n_matched", "tm_pct", "cm_pct", "target_recall", "n_first",
                "first_match_precision", "localisation_pct")
HEADERS = dict(n_target="target frames", n_same="look-alike frames", auroc_same="AUROC-same", n_matched="matched",
               tm_pct="TM %", cm_pct="CM %", target_recall="recall %", n_first="first matches",
               first_match_precision="FM-prec %", localisation_pct="best point on target %")
DECIMALS = dict(auroc_same=3, tm_pct=1, cm_pct=1, target_recall=1, first_match_precision=1, localisation_pct=1)


def class_pixels(frames: pd.DataFrame, visibility: pd.DataFrame) -> np.ndarray:
    """Per row of ``frames`` (labelled frames: ``frame_id`` and the visibility flags), the pixel area of the object
    that decides its class: the target's (all its mask values), else the largest look-alike's, else the largest
    other object's; 0 where the frame shows nothing."""
    by_role = visibility.groupby(["role", "frame_id"]).pixels
    target, largest = by_role.sum(), by_role.max()
    out = np.zeros(len(frames), np.float64)
    cls = frame_classes(frames)
    for role, code, table in (("target", TM, target), ("same_category", CM, largest), ("other", GM, largest)):
        rows = cls == code
        out[rows] = frames.frame_id[rows].map(table.get(role, pd.Series(dtype=float))).to_numpy(np.float64)
    return np.nan_to_num(out, nan=0.0)


def bands_of(pixels: np.ndarray) -> np.ndarray:
    """Each area's band (0 .. len(BANDS) - 1, by ``BAND_EDGES``); ``NO_OBJECT`` for an area of 0."""
    pixels = np.asarray(pixels, np.float64)
    return np.where(pixels > 0, np.searchsorted(BAND_EDGES, pixels, side="right"), NO_OBJECT).astype(np.int64)


def best_point_hits(frames: pd.DataFrame, visibility: pd.DataFrame,
                    mask_of: Callable[[str], np.ndarray]) -> pd.DataFrame:
    """For every score-table row of ``frames`` whose frame shows the target: whether the matcher gave a point at all,
    and whether its best point (the highest point score; the first among equals) lies on the target's pixels in the
    instance mask ``mask_of(frame_id)`` (at floor(y), floor(x))."""
    target = visibility[visibility.role == "target"]
    values = target.groupby("frame_id").mask_value.apply(lambda v: np.asarray(v, np.int64))
    out = []
    for row in frames[frames.frame_id.isin(values.index)].itertuples(index=False):
        scores = np.asarray(row.point_scores, np.float64)
        if not len(scores):
            out.append((row.frame_id, False, False))
            continue
        k = int(np.argmax(scores))
        mask = mask_of(row.frame_id)
        x = int(np.clip(np.floor(row.points_x[k]), 0, mask.shape[1] - 1))
        y = int(np.clip(np.floor(row.points_y[k]), 0, mask.shape[0] - 1))
        out.append((row.frame_id, True, bool(np.isin(mask[y, x], values[row.frame_id]))))
    return pd.DataFrame(out, columns=["frame_id", "has_point", "hit"])


def _pct(num: float, den: float) -> float:
    return 100.0 * num / den if den else math.nan


def _first_matches(frames: pd.DataFrame, matched: np.ndarray) -> np.ndarray:
    """Per row (rows in episode and step order), whether it is its episode's first frame at or above sigma."""
    return matched & (pd.Series(matched).groupby(frames.episode_id.to_numpy()).cumsum().to_numpy() == 1)


def size_table(scored: pd.DataFrame, visibility: pd.DataFrame, sigma: float,
               hits: pd.DataFrame | None = None) -> pd.DataFrame:
    """The ranking and threshold figures per band (rows ``BANDS``, then ``ALL``), at ``sigma``.

    ``scored``: a scored split (``EvalContext.scored``); ``hits``: ``best_point_hits`` of its table, or None for no
    localisation column. Per band: the target frames and look-alike frames whose deciding object is in it and
    AUROC-same between them; the matched frames in it and the shares of them that show the target (TM) or a
    look-alike (CM); the share of its target frames matched (recall); the episodes whose first match falls in it and
    the share of those that is the target (first-match precision); the share of its target frames whose best point
    lies on the target. NaN where a share has nothing to count.
    """
    frames = scored.sort_values(["episode_id", "step"]).reset_index(drop=True)
    cls = frame_classes(frames)
    band = bands_of(class_pixels(frames, visibility))
    score = frames.score.to_numpy(np.float64)
    matched = score >= sigma
    first = _first_matches(frames, matched)
    hit = frames.frame_id.isin([] if hits is None else hits.frame_id[hits.hit]).to_numpy(bool)
    rows = {}
    for name, sel in [*((b, band == k) for k, b in enumerate(BANDS)), (ALL, np.ones(len(frames), bool))]:
        tm, cm, m = sel & (cls == TM), sel & (cls == CM), sel & matched
        rows[name] = dict(
            n_target=int(tm.sum()), n_same=int(cm.sum()), auroc_same=auroc(score[tm], score[cm]),
            n_matched=int(m.sum()), tm_pct=_pct((m & tm).sum(), m.sum()), cm_pct=_pct((m & cm).sum(), m.sum()),
            target_recall=_pct((m & tm).sum(), tm.sum()), n_first=int((sel & first).sum()),
            first_match_precision=_pct((sel & first & (cls == TM)).sum(), (sel & first).sum()),
            localisation_pct=math.nan if hits is None else _pct((hit & tm).sum(), tm.sum()))
    table = pd.DataFrame.from_dict(rows, orient="index").rename_axis("band")
    return table[list(SIZE_COLUMNS)]


def readable(table: pd.DataFrame) -> pd.DataFrame:
    """``size_table``'s columns under the headers a person reads, AUROC to 3 decimals, shares to 1."""
    return table[list(SIZE_COLUMNS)].round(DECIMALS).rename(columns=HEADERS)


def paired_size_rows(scored_a: pd.DataFrame, scored_b: pd.DataFrame, visibility: pd.DataFrame, *,
                     clusters: Mapping[str, str] | None = None, names: tuple[str, str] = ("A", "B"),
                     boot: Bootstrap = DEFAULT_BOOT) -> pd.DataFrame:
    """AUROC-same per band of A and B, B - A and its paired bootstrap interval, in ``paired.paired_comparison``'s
    columns (rows ``AUROC-same <band> px``): the same resamples of target instances (``clusters``) as its rows, each
    band's target and look-alike frames reweighted by how often their instance was drawn."""
    both = align(scored_a, scored_b, names)
    cls = frame_classes(both)
    band = bands_of(class_pixels(both, visibility))
    episode, episode_ids = pd.factorize(both.episode_id)
    draws = list(episode_weights(unit_codes(list(episode_ids), clusters), boot))
    rows = {}
    for k, name in enumerate(BANDS):
        tm, cm = (band == k) & (cls == TM), (band == k) & (cls == CM)
        keep = tm | cm
        a, b = (_WeightedAuroc(both[f"score_{side}"].to_numpy(np.float64)[keep], tm[keep], cm[keep])
                for side in ("a", "b"))
        ep = episode[keep]
        point = [side(np.ones(len(ep))) for side in (a, b)]
        low, high = percentile_interval(np.array([b(w[ep]) - a(w[ep]) for w in draws]), boot.level)
        rows[f"AUROC-same {name} px"] = {names[0]: point[0], names[1]: point[1],
                                         f"{names[1]} - {names[0]}": point[1] - point[0], "CI low": low,
                                         "CI high": high}
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("Metric")


class _WeightedAuroc:
    """AUROC of one matcher's scores on fixed frames, each frame counted as often as a resample says."""

    def __init__(self, scores: np.ndarray, positive: np.ndarray, negative: np.ndarray) -> None:
        values, self.inverse = np.unique(scores, return_inverse=True)
        self.n_values = len(values)
        self.positive, self.negative = positive.astype(np.float64), negative.astype(np.float64)

    def __call__(self, weights: np.ndarray) -> float:
        return weighted_auroc(self.inverse, self.n_values, self.positive, self.negative, weights)
