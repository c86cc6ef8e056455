"""What looking further buys and costs: SR, CE, SPL and Steps against the look-further window, per matcher.

A look-further policy (``stop.LookFurther``) trades steps for the comparison inside the house:
the longer the agent looks after its first firing, the likelier the best candidate it saw is the
target, and the more steps and path it spends (the frames walked on and the walk back). ``trade``
reads each policy as an agent would meet it: sigma tuned for the policy on the tuning split,
read on the reported one, so a researcher picks the window knowing its price. Where the frame-set
has no geometry the rows carry what the agent committed to instead (``commits``), and sigma is
tuned by the first-match objective unless another is asked for (``default_objective``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.commits import commit_metrics, commitments
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.navigation import REJECTION_KEYS, episodes_at, navigation_metrics, walk_decisions
from pin_match.evaluation.core.policies import tune_policy
from pin_match.evaluation.core.stop import LookFurther, StopPolicy
from pin_match.evaluation.core.tuning import DEFAULT_OBJECTIVE
from pin_match.evaluation.pages.plots import plot_trade
from pin_match.scoring.table import ScoreTable

DEFAULT_WINDOWS = ("look:0", "look:10", "look:20", "look:40", "look:rest")
TRADE_KEYS = ("sr", "ce", "spl", "d2g", "steps", "not_found_pct", "commit_target_pct", "commit_lookalike_pct",
              "still_looking_pct", "frames_looked_at", *REJECTION_KEYS)


def default_objective(fs: FrameSet) -> str:
    """What a policy's sigma maximises when none is asked for: SR where the frame-set has the geometry the navigation
    estimate needs; else the first-match objective, which under a policy is the share of episodes it committed to
    the target, the question a set without geometry still answers."""
    return "sr" if fs.navigation_missing is None else DEFAULT_OBJECTIVE


def trade(ctx: EvalContext, tables: Mapping[str, ScoreTable], policies: Sequence[StopPolicy], *,
          objective: str | None = None, tune_split: str = "train", read_split: str = "val") -> pd.DataFrame:
    """One row per (matcher, policy): sigma tuned for the policy by ``objective`` (default: ``default_objective``) on
    ``tune_split``, then on ``read_split`` the navigation estimate (SR, CE, SPL, D2G, Steps, with SR's and CE's
    intervals; NaN without geometry) and what the policy committed to (% of episodes committed to the target and to a
    look-alike, still looking when the walk ended (part of not found), frames looked at). ``window``: the policy's
    window in frames (NaN for the rest of the walk, for other policies)."""
    rows = []
    geometry = ctx.fs.navigation_missing is None
    objective = objective or default_objective(ctx.fs)
    for name, table in tables.items():
        for policy in policies:
            tuned = tune_policy(table, ctx, policy, objective=objective, split=tune_split)
            sigma, policy = float(tuned["sigma"]), StopPolicy.parse(tuned["policy"])  # an approach's line is tuned too
            decisions = walk_decisions(ctx.placements(table, read_split), sigma, policy)[0] if geometry else None
            committed = commit_metrics(commitments(ctx.arrays(table, read_split), sigma, policy, decisions),
                                       ctx.clusters, ctx.boot)
            metrics, ci = dict(committed["metrics"]), dict(committed["ci95"])
            if geometry:
                walks = navigation_metrics(episodes_at(ctx.placements(table, read_split), sigma, policy),
                                           ctx.clusters, ctx.boot)
                metrics |= walks["metrics"]
                ci |= walks["ci95"]
            window = policy.window if isinstance(policy, LookFurther) else None
            rows.append(dict(matcher=name, matcher_id=table.matcher_id, policy=str(policy),
                             window=math.nan if window is None else window, upper_bound=_upper_bound(policy),
                             sigma=sigma, **{key: metrics.get(key, math.nan) for key in TRADE_KEYS},
                             **{f"{key}_{end}": (ci.get(key) or [math.nan, math.nan])[i]
                                for key in ("sr", "ce", "commit_target_pct") for i, end in enumerate(("low", "high"))}))
    return pd.DataFrame(rows)


def _upper_bound(policy: StopPolicy) -> bool:
    return isinstance(policy, LookFurther) and policy.upper_bound


def write_trade(rows: pd.DataFrame, out: str | Path, title: str = "") -> tuple[Path, Path]:
    """``trade``'s rows as trade.csv and their picture, trade.png, in ``out``."""
    out = Path(out)
    atomic.write_text(out / "trade.csv", rows.to_csv(index=False))
    plot_trade(rows, out / "trade.png", title)
    return out / "trade.csv", out / "trade.png"
