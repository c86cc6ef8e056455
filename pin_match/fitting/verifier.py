"""Fit a ``verify`` file: logistic regression on the signals of candidate regions of train splits.

The verifier (``matchers/verify.py``) scores candidate regions, not frames, so it is fitted on
candidates: one drawn on the target (it holds at least half of the target's visible pixels,
or the target fills a quarter of it) is a positive; every candidate of a frame without the
target is a negative, of the same-category class when a look-alike is in view and of the
other class otherwise; a candidate beside the target in a target frame says nothing about
the target's signals and is left out. The three classes weigh the same, as in the score
fusion (``labels.class_weights``). The signals of every candidate of a frame-set are computed
once and cached by the score cache's folder rule (the matcher's ``signals_id``, the frame-set's
fingerprint; metadata checked), so fits, ablations (signals left out) and evaluations reuse
them; the frame score from cached signals is the matcher's own.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa

import pin_match
from pin_match import atomic, outputs
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.labels import TM, UNUSED, class_weights, frame_classes, frame_labels
from pin_match.fitting.logistic import FitError, logistic_fit, require_classes
from pin_match.matchers.verify import (
    SIGNALS,
    VERIFIER_FORMAT,
    VERIFIER_VERSION,
    VerifyMatcher,
    color_shortfall,
    read_verifier,
    verdict,
)
from pin_match.scoring.cache import cache_dir, read_meta
from pin_match.scoring.schema import encode_meta

ON_TARGET_SHARE = 0.5  # of the target's visible pixels inside the box ...
TARGET_FILL = 0.25     # ... or of the box covered by the target


def target_share(box: Sequence[int], target: np.ndarray) -> float:
    """The share of the target's visible pixels (the boolean mask ``target``) inside a box; 0 without a target."""
    total = int(target.sum())
    x0, y0, x1, y1 = box
    return int(target[y0:y1, x0:x1].sum()) / total if total else 0.0


def on_target(box: Sequence[int], target: np.ndarray) -> bool:
    """Whether a candidate box is drawn on the target, whose visible pixels are the boolean mask ``target``."""
    total = int(target.sum())
    if not total:
        return False
    x0, y0, x1, y1 = box
    inside = int(target[y0:y1, x0:x1].sum())
    return inside >= ON_TARGET_SHARE * total or inside >= TARGET_FILL * max((x1 - x0) * (y1 - y0), 1)


def candidate_table(fs: FrameSet, matcher: VerifyMatcher, *, out: str | Path = outputs.FEATURES, batch_size: int = 4,
                    progress: bool = False) -> pd.DataFrame:
    """One row per candidate of every frame of ``fs``: its box, whether it is on the target (and ``cover``, the
    share of the target's pixels inside the box), its signals.

    Cached by the score cache's folder rule, ``cache_dir(out, "verify-signals@<signals_id>",
    fingerprint)``, one file per set of splits (a split of a frame-set keeps the whole set's
    fingerprint, so it reads the whole set's file). A file counts when its metadata names this
    signals id and frame-set and it holds the signals asked for and every episode; a damaged
    file or another's is not a hit, and is computed again.
    """
    folder = cache_dir(out, f"verify-signals@{matcher.signals_id}", fs.fingerprint)
    episodes = set(fs.episodes.episode_id)
    for found in sorted(folder.glob("candidates_*.parquet")):  # this set, or the whole set it is a split of
        meta = read_meta(found) or {}
        if (meta.get("signals_id"), meta.get("frameset_fingerprint")) == (matcher.signals_id, fs.fingerprint) \
                and set(matcher.cfg.signals) <= set(meta["signals"]) and episodes <= set(meta["episodes"]):
            table = pd.read_parquet(found)
            return table[table.episode_id.isin(episodes)].reset_index(drop=True)
    table = compute_candidates(fs, matcher, batch_size, progress)
    store_candidates(fs, matcher, table, out)
    return table


def store_candidates(fs: FrameSet, matcher: VerifyMatcher, table: pd.DataFrame, out: str | Path) -> Path:
    """Write ``fs``'s candidate table where ``candidate_table`` finds it, with the metadata it checks."""
    signals = [s for s in SIGNALS if s in table.columns]
    meta = dict(kind="verify candidate signals", signals_id=matcher.signals_id, signals=signals,
                frameset_fingerprint=fs.fingerprint, frameset_name=fs.manifest.get("name", ""),
                episodes=sorted(set(fs.episodes.episode_id)), pin_match_version=pin_match.__version__)
    stored = pa.Table.from_pandas(table, preserve_index=False)
    stored = stored.replace_schema_metadata({**(stored.schema.metadata or {}), **encode_meta(meta)})
    path = cache_dir(out, f"verify-signals@{matcher.signals_id}", fs.fingerprint) \
        / f"candidates_{'+'.join(sorted(set(fs.episodes.split)))}.parquet"
    atomic.write_parquet(path, stored)
    return path


def compute_candidates(fs: FrameSet, matcher: VerifyMatcher, batch_size: int, progress: bool) -> pd.DataFrame:
    """``candidate_table``'s rows, computed: every episode's frames through ``candidate_signals``."""
    rows = []
    for n, episode in enumerate(fs.episodes.itertuples(), 1):
        matcher.prepare(fs.target(episode.target_object_id))
        frames = fs.frames[fs.frames.episode_id == episode.episode_id]
        for start in range(0, len(frames), batch_size):
            ids = list(frames.frame_id.iloc[start:start + batch_size])
            for frame_id, found in zip(ids, matcher.candidate_signals([fs.image(f) for f in ids])):
                target = fs.object_pixels(frame_id, episode.target_object_id)
                for k, (cand, signals) in enumerate(found):
                    rows.append(dict(frame_id=frame_id, episode_id=episode.episode_id, split=episode.split,
                                     candidate=k, x0=cand.box[0], y0=cand.box[1], x1=cand.box[2], y1=cand.box[3],
                                     on_target=on_target(cand.box, target), cover=target_share(cand.box, target),
                                     **signals))
        if progress:
            print(f"verify signals: {fs.root.name} episode {n}/{len(fs.episodes)}", file=sys.stderr)
    return pd.DataFrame(rows)


def candidate_classes(table: pd.DataFrame, labels: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray, dict[str, int]]:
    """The candidates a fit uses, their sample weights (each class summing to 1) and the class counts.

    A candidate has its frame's class (``labels.frame_classes``), except that in a target frame
    only a candidate on the target is a positive; the others there are left out.
    """
    of_frame = pd.Series(frame_classes(labels), index=labels.frame_id.to_numpy())
    classes = table.frame_id.map(of_frame).to_numpy(np.int8, copy=True)
    classes[(classes == TM) & ~table.on_target.to_numpy(bool)] = UNUSED
    weights, counts = class_weights(classes)
    require_classes(counts, "verifier fit")
    keep = classes != UNUSED
    return table[keep].reset_index(drop=True), weights[keep], counts


def fit_weights(used: pd.DataFrame, weights: np.ndarray, signals: Sequence[str], floor: float,
                l2: float) -> dict[str, Any]:
    """The verifier file's numbers fitted on candidates (``on_target`` and one column per signal): its
    ``intercept``, ``coefs`` and ``gate`` (``floor``, 0 for none, and the fitted slope).

    The colour weight and the colour penalty's slope are fitted under the constraint that they
    are not negative (``logistic_fit``'s ``nonnegative``): where the data would make either
    negative it is 0 and the other weights are refitted without it, so a candidate whose colour
    agrees less never scores higher (``read_verifier`` refuses a file that breaks this).
    """
    signals = list(signals)
    features = used[signals].to_numpy(float)
    if floor:  # the penalty's input is one more feature; its coefficient is the penalty's slope
        features = np.c_[features, [color_shortfall(c, floor) for c in used.color]]
    colour = [signals.index("color")] if "color" in signals else []
    beta = logistic_fit(features, used.on_target.to_numpy(float), weights, l2,
                        nonnegative=colour + ([len(signals)] if floor else []))
    return dict(intercept=float(beta[0]), coefs={s: float(c) for s, c in zip(signals, beta[1:])},
                gate=dict(floor=floor, coef=float(beta[-1]) if floor else 0.0))


def fit_verifier(framesets: Sequence[FrameSet | str | Path], path: str | Path, *, split: str = "train",
                 overrides: dict[str, Any] | None = None, out: str | Path = outputs.FEATURES, l2: float = 1.0,
                 progress: bool = False) -> dict[str, Any]:
    """Fit the signals' weights on ``split`` of every frame-set together and write the verifier file (atomically).

    ``overrides`` configure the ``verify`` matcher (``signals`` leaves some out, for an ablation);
    the file records its ``signals_id``, so the matcher refuses it for other signals. The numbers
    are ``fit_weights``': the colour weight and the colour penalty's slope are never negative.
    """
    matcher = create_matcher("verify", **(overrides or {}))
    tables, labels, sources = [], [], []
    for i, item in enumerate(framesets):
        fs = item if isinstance(item, FrameSet) else FrameSet.load(item)
        table = candidate_table(fs, matcher, out=out, progress=progress)
        # two variants of one source share frame ids: the set's position keeps them apart
        tables.append(table[table.split == split].assign(frame_id=lambda t, i=i: f"{i}:" + t.frame_id))
        labels.append(frame_labels(fs).assign(frame_id=lambda t, i=i: f"{i}:" + t.frame_id))
        sources.append(dict(frameset=fs.manifest.get("name", str(fs.root)), fingerprint=fs.fingerprint))
    used, weights, counts = candidate_classes(pd.concat(tables, ignore_index=True), pd.concat(labels))
    spec = dict(format=VERIFIER_FORMAT, version=VERIFIER_VERSION, signals_id=matcher.signals_id,
                **fit_weights(used, weights, matcher.cfg.signals, matcher.cfg.color_gate, l2),
                fitted_on=dict(framesets=sources, split=split, candidates=len(used), classes=counts, l2=l2,
                               objective="weighted logistic regression, candidate on the target vs candidates of "
                                         "frames without it; target, same-category and other classes weigh the "
                                         "same"))
    atomic.write_json(path, spec)
    read_verifier(Path(path))  # what was written is what the matcher accepts
    return spec


def frame_scores(table: pd.DataFrame, spec: dict[str, Any]) -> pd.DataFrame:
    """Per frame, the verifier's score from cached candidate signals: its best candidate's probability."""
    missing = set(spec["coefs"]) - set(table.columns)
    if missing:
        raise FitError(f"candidate table has no signal {sorted(missing)[0]!r} (of {', '.join(SIGNALS)})")
    probability = [verdict(spec, row) for row in table[list(spec["coefs"])].to_dict("records")]
    scored = table[["frame_id"]].assign(score=probability)
    return scored.groupby("frame_id", sort=False, as_index=False).score.max()
