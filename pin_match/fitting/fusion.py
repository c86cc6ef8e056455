"""Fit a ``fusion`` file: logistic regression on component matchers' cached scores of a train split.

The fusion matcher (``matchers/fusion.py``) only applies weights; fitting needs score tables
and labels, which live above the matchers, so it is here. The components are scored through
``pin_match.scoring.score_many`` (one pass over the frames) with the usual cache (a table
already there is read, never recomputed). Frames are the positives when the target is
visible; the negatives are split by the metrics' frame classes into same-category look-alike
frames and all other frames, and the three classes weigh the same in the loss
(``labels.class_weights``). The file records the components (name, config, id), the
frame-set's fingerprint and the split, so what a fusion was fitted on is never guessed."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pin_match import atomic, outputs
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.labels import TM, class_weights, frame_classes, scored_frames
from pin_match.fitting.logistic import FitError, logistic_fit, require_classes
from pin_match.matchers.common.fusion_file import FUSION_FORMAT, FUSION_VERSION, TRANSFORMS, read_fusion
from pin_match.scoring import DEFAULT_RUN, RunOptions, score_many

Component = tuple[str, dict[str, Any], str]  # matcher name, config overrides, transform


def fit_classes(labels: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """(y, sample weight, class counts) of labelled frames: the target is y = 1, each fit class weighs the same."""
    classes = frame_classes(labels)
    weights, counts = class_weights(classes)
    require_classes(counts, "fusion fit")
    return (classes == TM).astype(float), weights, counts


def component_scores(fs: FrameSet, components: list[Component], split: str, out: str | Path,
                     run: RunOptions) -> tuple[pd.DataFrame, list[dict[str, Any]]]:
    """Labels of the split's frames with one score column per component, and the components' records; the
    components are scored together, in one pass over the frames (``scoring.score_many``)."""
    for name, _, transform in components:
        if transform not in TRANSFORMS:
            raise FitError(f"fusion component {name}: transform {transform!r}; choose one of {sorted(TRANSFORMS)}")
    matchers = [create_matcher(name, **overrides) for name, overrides, _ in components]
    tables = score_many(fs, matchers, split=split, out=out, run=run)
    ctx = EvalContext(fs)
    labels = ctx.split_labels(split).reset_index(drop=True)
    records = []
    for i, ((name, _, transform), matcher, table) in enumerate(zip(components, matchers, tables)):
        scored = scored_frames(labels, table)
        labels[f"s{i}"] = labels.frame_id.map(dict(zip(scored.frame_id, scored.score)))
        records.append(dict(matcher=name, config=resolved_config(matcher), id=matcher.id, transform=transform))
    missing = labels[[f"s{i}" for i in range(len(components))]].isna().any(axis=1)
    if missing.any():
        raise FitError(f"fusion fit: frame {labels.frame_id[missing].iloc[0]!r} has no score in some component")
    return labels, records


def fit_fusion(frameset: FrameSet | str | Path, components: list[Component], path: str | Path, *,
               split: str = "train", out: str | Path = outputs.SCORES, l2: float = 1.0,
               run: RunOptions = DEFAULT_RUN) -> dict[str, Any]:
    """Fit the weights on ``split`` of ``frameset`` and write the fusion file to ``path`` (atomically).

    ``components`` are (matcher name, config overrides, transform); the fusion returns the first
    component's points (``points_from`` 0), so put one that always has points, such as a patch matcher, first.
    """
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    labels, records = component_scores(fs, components, split, out, run)
    y, weights, counts = fit_classes(labels)
    x = np.column_stack([[TRANSFORMS[r["transform"]](float(s)) for s in labels[f"s{i}"]]
                         for i, r in enumerate(records)])
    beta = logistic_fit(x, y, weights, l2)
    for record, coef in zip(records, beta[1:]):
        record["coef"] = float(coef)
    spec = dict(format=FUSION_FORMAT, version=FUSION_VERSION, intercept=float(beta[0]), components=records,
                points_from=0,
                fitted_on=dict(frameset=fs.manifest.get("name", str(fs.root)), fingerprint=fs.fingerprint, split=split,
                               frames=len(labels), classes=counts, l2=l2,
                               objective="weighted logistic regression, target vs rest; target, same-category "
                                         "look-alike and other frames weigh the same"))
    atomic.write_json(path, spec)
    read_fusion(Path(path))  # what was written is what the matcher accepts
    return spec


def resolved_config(matcher) -> dict[str, Any]:
    """Every config value the matcher's id hashes, defaults included: a later change of a default never
    changes which component a fusion file names."""
    return json.loads(json.dumps({k: v for k, v in matcher.cfg.hashed_dict().items() if v is not None}))
