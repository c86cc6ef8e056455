"""Fit a ``verify`` file: logistic regression on the signals of candidate regions of train splits.

The verifier (``matchers/verify.py``) scores candidate regions, not frames, so it is fitted on
candidates: one drawn on the target (it holds at least half of the target's visible pixels,
or the target fills a quarter of it) is a positive; every candidate of a frame without the
target is a negative, of the same-category class when a look-alike is in view and of the
other class otherwise; a candidate beside the target in a target frame says nothing about
the target's signals and is left out. The three classes weigh the same, as in the score
fusion (``labels.class_weights``). The signals of every candidate of a frame-set are a per-frame
product of the scoring engine (``CandidateSignals``: chunks, resume, Dask, progress, the score
cache's rule), computed once, so fits, ablations (signals left out) and evaluations reuse them;
the frame score from cached signals is the matcher's own.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd
import pyarrow as pa

import pin_match
from pin_match import atomic, outputs
from pin_match.contract.frames import Frames
from pin_match.contract.matcher import Matcher
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.labels import TM, UNUSED, class_weights, frame_classes
from pin_match.evaluation.flows.carry import pooled
from pin_match.fitting.logistic import FitError, logistic_fit, require_classes
from pin_match.matchers.common.verifier_file import (
    DEFAULT_SIGNALS,
    SIGNALS,
    VERIFIER_FORMAT,
    VERIFIER_VERSION,
    color_shortfall,
    read_verifier,
    verdict,
)
from pin_match.scoring.api import run_jobs
from pin_match.scoring.cache import Shard
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.product import Job, Product
from pin_match.scoring.schema import as_stored

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


@dataclass(frozen=True)
class CandidateSignals(Product):
    """``verify``'s candidates of every frame with their signals: a per-frame product of the scoring engine.

    One row per candidate: its frame, box, whether it is on the target (and ``cover``, the share
    of the target's pixels inside the box) and one column per signal of ``signals``. Its cache
    folder hashes the matcher's ``signals_id`` with the signals computed, so an ablation's fits
    (subsets of them) and every evaluation read one table. The matcher is a ``verify``, built by
    name (``create_matcher("verify", ...)``), as everywhere in fitting: the plug-in is never imported.
    """

    signals: tuple[str, ...] = DEFAULT_SIGNALS
    prefix: ClassVar[str] = "candidates"

    def folder(self, matcher: Matcher) -> str:
        payload = json.dumps([matcher.signals_id, list(self.signals)])
        return f"verify-signals@{hashlib.sha256(payload.encode()).hexdigest()[:12]}"

    def compute(self, matcher: Matcher, frames: Frames) -> list[Any]:
        return matcher.candidate_signals(frames)

    def rows(self, fs: FrameSet, episode: Any, frame_ids: list[str], steps: np.ndarray,
             results: list[Any]) -> pd.DataFrame:
        rows = []
        for frame_id, found in zip(frame_ids, results):
            target = fs.object_pixels(frame_id, episode.target_object_id)
            for k, (cand, signals) in enumerate(found):
                rows.append(dict(frame_id=frame_id, episode_id=episode.episode_id, split=str(episode.split),
                                 candidate=k, x0=cand.box[0], y0=cand.box[1], x1=cand.box[2], y1=cand.box[3],
                                 on_target=on_target(cand.box, target), cover=target_share(cand.box, target),
                                 **{s: signals[s] for s in self.signals}))
        return pd.DataFrame(rows, columns=self.schema().names)

    def schema(self) -> Any:
        return pa.schema([(c, pa.large_string()) for c in ("frame_id", "episode_id", "split")]
                         + [(c, pa.int64()) for c in ("candidate", "x0", "y0", "x1", "y1")]
                         + [("on_target", pa.bool_()), ("cover", pa.float64())]
                         + [(s, pa.float64()) for s in self.signals])

    def meta(self, matcher: Matcher, fs: FrameSet, split: str | None, shard: Shard | None) -> dict:
        return as_stored(dict(kind="verify candidate signals", signals_id=matcher.signals_id,
                              signals=list(self.signals), frameset_fingerprint=fs.fingerprint,
                              frameset_name=fs.manifest.get("name", ""), split=split or "all",
                              shard=str(shard) if shard else None, pin_match_version=pin_match.__version__))


def candidate_table(fs: FrameSet, matcher: Matcher, *, split: str | None = None,
                    out: str | Path = outputs.FEATURES, run: RunOptions = DEFAULT_RUN) -> pd.DataFrame:
    """The candidates of every frame of ``split`` with the matcher's signals (``CandidateSignals``).

    Computed by the scoring engine into ``cache_dir(out, "verify-signals@<hash>", fingerprint)``:
    per-episode chunks (a killed run resumes), Dask with ``run.client``, the progress bar, and
    the score cache's rule (a table counts when its metadata is this run's).
    """
    product = CandidateSignals(tuple(matcher.cfg.signals))
    (path,) = run_jobs(fs, [Job(matcher, product)], split=split, out=out, run=run)
    return pd.read_parquet(path)


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


def fit_verifier(framesets: Sequence[FrameSet | str | Path | EvalContext], path: str | Path, *, split: str = "train",
                 overrides: dict[str, Any] | None = None, out: str | Path = outputs.FEATURES, l2: float = 1.0,
                 run: RunOptions = DEFAULT_RUN) -> dict[str, Any]:
    """Fit the signals' weights on ``split`` of every frame-set together and write the verifier file (atomically).

    ``overrides`` configure the ``verify`` matcher (``signals`` leaves some out, for an ablation);
    the file records its ``signals_id``, so the matcher refuses it for other signals. The numbers
    are ``fit_weights``': the colour weight and the colour penalty's slope are never negative. A
    frame-set given as an ``EvalContext`` lends its labels, built once for the whole run.
    """
    matcher = create_matcher("verify", **(overrides or {}))
    contexts = [EvalContext.of(item) for item in framesets]
    tables = [candidate_table(ctx.fs, matcher, split=split, out=out, run=run) for ctx in contexts]
    spec = fit_spec(matcher, [(ctx.fs, ctx.labels, table) for ctx, table in zip(contexts, tables)], split, l2)
    atomic.write_json(path, spec)
    read_verifier(Path(path))  # what was written is what the matcher accepts
    return spec


def fit_spec(matcher: Matcher, sets: Sequence[tuple[FrameSet, pd.DataFrame, pd.DataFrame]], split: str,
             l2: float) -> dict[str, Any]:
    """The verifier file of ``matcher``'s signals and colour gate, fitted on ``split`` of each (frame-set, its
    labels, a candidate table holding those signals); a FitError when there is nothing to fit on."""
    if not sets:
        raise FitError("verifier fit: no frame-set to fit on")
    tables = [table[table.split == split] for _, _, table in sets]
    if all(t.empty for t in tables):
        roots = ", ".join(str(fs.root) for fs, _, _ in sets)
        raise FitError(f"verifier fit: no candidate in split {split!r} of {roots}")
    # two variants of one source share frame ids: ``pooled`` keeps them apart by the set's position
    used, weights, counts = candidate_classes(pooled(tables), pooled([fs_labels for _, fs_labels, _ in sets]))
    sources = [dict(frameset=fs.manifest.get("name", str(fs.root)), fingerprint=fs.fingerprint) for fs, _, _ in sets]
    return dict(format=VERIFIER_FORMAT, version=VERIFIER_VERSION, signals_id=matcher.signals_id,
                **fit_weights(used, weights, matcher.cfg.signals, matcher.cfg.color_gate, l2),
                fitted_on=dict(framesets=sources, split=split, candidates=len(used), classes=counts, l2=l2,
                               objective="weighted logistic regression, candidate on the target vs candidates of "
                                         "frames without it; target, same-category and other classes weigh the "
                                         "same"))


def frame_scores(table: pd.DataFrame, spec: dict[str, Any]) -> pd.DataFrame:
    """Per frame, the verifier's score from cached candidate signals: its best candidate's probability."""
    missing = set(spec["coefs"]) - set(table.columns)
    if missing:
        raise FitError(f"candidate table has no signal {sorted(missing)[0]!r} (of {', '.join(SIGNALS)})")
    probability = [verdict(spec, row) for row in table[list(spec["coefs"])].to_dict("records")]
    scored = table[["frame_id"]].assign(score=probability)
    return scored.groupby("frame_id", sort=False, as_index=False).score.max()
