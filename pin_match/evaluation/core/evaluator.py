"""One matcher's detection metrics on one split at one sigma, from a score table and its frame-set.

``check_frameset`` is the single test that scores and frame-set belong together; ``tune``,
``evaluate`` and the CLI all call it, so a table is never read against another frame-set's
labels. An ``EvalContext`` is what every step of a run reads: the frame-set, its labels (built
once), each table's scored split (converted to ``FrameArrays`` once) and the bootstrap options.
``bench``, ``report``, ``tune`` and ``compare`` take it where they take a frame-set, so a bench
of several matchers builds the labels once without threading them through every call.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import pandas as pd

from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.commits import commit_metrics, commitments
from pin_match.evaluation.core.intervals import bootstrap_ci, instance_clusters
from pin_match.evaluation.core.labels import frame_labels, localisation_hits, scored_frames
from pin_match.evaluation.core.metrics import (
    DEFAULT_BOOT,
    Bootstrap,
    FrameArrays,
    detection_metrics,
    frame_arrays,
    localisation_metrics,
    per_category,
)
from pin_match.evaluation.core.navigation import episodes_at, navigation_metrics, walk_decisions
from pin_match.evaluation.core.placements import Placements, WalkUpViews
from pin_match.evaluation.core.sigma import SigmaChoice, way_out
from pin_match.evaluation.core.stop import FIRST_MATCH, Decision, StopPolicy
from pin_match.scoring.table import ScoreTable


class EvaluationError(PinMatchError, ValueError):
    """Scores, frame-set and split do not belong together."""


def check_frameset(table: ScoreTable, fs: FrameSet) -> None:
    """Refuse a score table computed on another frame-set (or one that does not say which)."""
    fingerprint = table.meta.get("frameset_fingerprint")
    if fingerprint != fs.fingerprint:
        raise EvaluationError(f"score table of {table.matcher_id} was computed on frame-set {fingerprint}, "
                              f"not on {fs.root} ({fs.fingerprint}): pass the frame-set it was scored on")


class EvalContext:
    """One frame-set as every evaluation step of a run reads it: labels built once, each scored split once.

    ``boot`` resamples every interval the run computes. ``walk_ups``: where a table's walk-up views come from, for
    an approach-verify policy (``scoring.walkups.walkup_scorer``: rendered and scored by the table's matcher).
    """

    def __init__(self, fs: FrameSet, boot: Bootstrap = DEFAULT_BOOT,
                 walk_ups: Callable[[ScoreTable], WalkUpViews | None] | None = None) -> None:
        self.fs = fs
        self.boot = boot
        self.walk_ups = walk_ups
        self._scored: dict[tuple[int, str | None], tuple[ScoreTable, pd.DataFrame, FrameArrays]] = {}
        self._placements: dict[tuple[int, str | None], Placements] = {}

    @classmethod
    def of(cls, data: FrameSet | str | Path | EvalContext) -> EvalContext:
        """``data`` itself when it is a context, else a new one (default options) of the frame-set or its folder."""
        if isinstance(data, EvalContext):
            return data
        return cls(data if isinstance(data, FrameSet) else FrameSet.load(data))

    @cached_property
    def labels(self) -> pd.DataFrame:
        """``frame_labels`` of the frame-set."""
        return frame_labels(self.fs)

    def split_labels(self, split: str | None) -> pd.DataFrame:
        """``labels`` of one split's frames (all of them for None)."""
        return self.labels if split in (None, "all") else self.labels[self.labels.split == split]

    @cached_property
    def clusters(self) -> dict[str, str]:
        """Each episode's resampling unit for every interval of the run: its target instance."""
        return instance_clusters(self.fs.episodes)

    def scored(self, table: ScoreTable, split: str | None) -> pd.DataFrame:
        """The frame labels of one split's scored frames with their score; a missing split says how to go on."""
        return self._split(table, split)[1]

    def arrays(self, table: ScoreTable, split: str | None) -> FrameArrays:
        """``scored`` as the arrays every metric reads."""
        return self._split(table, split)[2]

    def placements(self, table: ScoreTable, split: str | None) -> Placements:
        """``navigation.Placements`` of one split (each frame's points placed in the house once, for every sigma);
        a frame-set without geometry or depth raises ``NavigationError`` saying so."""
        key = (id(table), None if split in (None, "all") else split)
        if key not in self._placements:
            _, scored, arr = self._split(table, split)
            self._placements[key] = Placements(self.fs, scored, arr, table.frames, self.approach_scored(table, split),
                                               None if self.walk_ups is None else self.walk_ups(table))
        return self._placements[key]

    def approach_scored(self, table: ScoreTable, split: str | None) -> pd.DataFrame:
        """The frame labels of one split's scored approach views with their score (empty where the set has none)."""
        scored = scored_frames(self.labels, table, approach=True)
        return scored if split in (None, "all") else scored[scored.split == split].reset_index(drop=True)

    def _split(self, table: ScoreTable, split: str | None) -> tuple[ScoreTable, pd.DataFrame, FrameArrays]:
        key = (id(table), None if split in (None, "all") else split)
        if key not in self._scored:  # the table is kept with its entry, so its id is never reused while cached
            check_frameset(table, self.fs)
            scored = scored_frames(self.labels, table)
            if key[1] is not None:
                scored = scored[scored.split == split].reset_index(drop=True)
            if scored.empty:
                raise EvaluationError(way_out(table.matcher_id, str(split), sorted(set(table.frames.split))))
            self._scored[key] = (table, scored, frame_arrays(scored))
        return self._scored[key]


def split_frames(table: ScoreTable, data: FrameSet | EvalContext, split: str | None) -> pd.DataFrame:
    """The frame labels of one split's scored frames with their score (``EvalContext.scored``)."""
    return EvalContext.of(data).scored(table, split)


@dataclass(frozen=True)
class Evaluation:
    """One matcher on one split at one sigma: metrics.json's content, the per-category table, and the split's
    scored frames as a table (the report page's galleries need its ids and visibility) and as arrays."""

    result: dict
    per_category: pd.DataFrame
    frames: pd.DataFrame
    arrays: FrameArrays
    walks: pd.DataFrame | None = None  # per episode, where the agent stopped (``navigation``); None without geometry
    policy: StopPolicy = FIRST_MATCH  # the stop policy the navigation estimate and the commitments are read under
    commits: pd.DataFrame | None = None  # per episode, what the policy committed to (``commits``); None for PIN's rule
    decisions: list[Decision] | None = None  # the policy's, made once with what the house says (None without geometry)


def evaluate(table: ScoreTable, data: FrameSet | EvalContext, sigma: SigmaChoice, split: str | None = "val",
             policy: StopPolicy = FIRST_MATCH) -> Evaluation:
    """Metrics (with CIs and localisation), the navigation estimate where the frame-set has geometry, and the
    per-category table of one split at one sigma. The frame metrics read sigma alone; the navigation estimate,
    and for a policy other than PIN's rule what it committed to per episode (``commits``), read ``policy``."""
    ctx = EvalContext.of(data)
    scored, arr = ctx.scored(table, split), ctx.arrays(table, split)
    metrics = detection_metrics(arr, sigma.value)
    hits = localisation_hits(ctx.fs, table_subset(table, scored.frame_id), sigma.value)
    metrics.update(localisation_metrics(hits))
    ci95 = bootstrap_ci(arr, sigma.value, clusters=ctx.clusters, boot=ctx.boot)
    walks, navigation = None, {"missing": ctx.fs.navigation_missing}
    if navigation["missing"] is None:
        walks = episodes_at(ctx.placements(table, split), sigma.value, policy)
        estimate = navigation_metrics(walks, ctx.clusters, ctx.boot)
        metrics.update(estimate.pop("metrics"))
        ci95.update(estimate.pop("ci95"))
        navigation = {"policy": policy.describe(), **estimate}
    commits = None
    decisions = None if walks is None else walk_decisions(ctx.placements(table, split), sigma.value, policy)[0]
    if policy != FIRST_MATCH:
        commits = commitments(arr, sigma.value, policy, decisions)
        committed = commit_metrics(commits, ctx.clusters, ctx.boot)
        metrics.update(committed["metrics"])
        ci95.update(committed["ci95"])
    result = dict(matcher=table.matcher, matcher_id=table.matcher_id, config_hash=table.meta.get("config_hash"),
                  modality=table.meta.get("modality"), frameset_fingerprint=ctx.fs.fingerprint, split=split or "all",
                  **sigma.as_dict(), policy=str(policy), metrics=metrics, ci95=ci95, navigation=navigation,
                  n_bootstrap=ctx.boot.n_boot, date=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))
    return Evaluation(result, per_category(arr, sigma.value), scored, arr, walks, policy, commits, decisions)


def table_subset(table: ScoreTable, frame_ids: pd.Series) -> ScoreTable:
    return ScoreTable(table.frames[table.frames.frame_id.isin(frame_ids)].reset_index(drop=True), table.meta)
