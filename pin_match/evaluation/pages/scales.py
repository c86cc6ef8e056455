"""Where each target's score scale comes from: a normalised matcher's cohort beside the target's own scores.

A cohort-normalised score (``cohort-norm``) is 0.5 where the target's closest cohort members
score, so one sigma carries only as far as a house's look-alikes score like those members (the
normalisation's assumption). Per target the report shows the raw score that maps to 0.5, the
spread, the closest members with their raw scores, and beside them the target's frames and its
look-alikes in both units: a look-alike far above every cohort member is a house the cohort did
not foresee. Read from the score table's per-target notes; nothing runs a matcher.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pin_match.contract.cohort import TargetCohort
from pin_match.evaluation.pages.gallery import frame_roles
from pin_match.scoring.table import ScoreTable, ScoreTableError

LOOKALIKE = "same-category look-alike"  # gallery.ROLE_NAMES' name of a same-category frame
COLUMNS = ["target", "category", "raw score at 0.5", "spread (logit)", "closest cohort members (raw score)",
           "target frames: median (raw)", "look-alike frames: highest (raw)", "look-alikes above sigma"]


def target_cohorts(table: ScoreTable) -> dict[str, TargetCohort]:
    """The cohort each target was read against (empty for a matcher whose scores are raw)."""
    out = {}
    for target_id, notes in table.target_notes.items():
        try:
            cohort = TargetCohort.from_notes(notes)
        except ValueError as exc:
            raise ScoreTableError(f"score table of {table.matcher_id}, target {target_id!r}: {exc}") from exc
        if cohort is not None:
            out[target_id] = cohort
    return out


def scale_table(cohorts: dict[str, TargetCohort], scored: pd.DataFrame, targets: pd.Series, sigma: float,
                shown: int = 3) -> pd.DataFrame:
    """One row per target of ``scored`` with a cohort: the scale (raw score at 0.5, spread, the ``shown`` closest
    members) beside its frames' scores, normalised and raw.

    ``targets``: each episode's target id, indexed by episode id.
    """
    scored = scored.assign(role=frame_roles(scored), target_id=scored.episode_id.map(targets))
    rows = []
    for target_id, frames in scored.groupby("target_id", sort=True):
        cohort = cohorts.get(target_id)
        if cohort is None:
            continue
        imp = cohort.impostors
        own = frames.score[frames.role == "target"].to_numpy()
        alike = frames.score[frames.role == LOOKALIKE].to_numpy()
        rows.append({
            "target": target_id, "category": frames.target_category.iloc[0],
            "raw score at 0.5": round(cohort.midpoint, 4), "spread (logit)": round(imp.std, 3),
            "closest cohort members (raw score)": ", ".join(f"{n} {s:.3f}" for n, s in cohort.closest[:shown]),
            "target frames: median (raw)": _both(imp, np.median(own)) if own.size else "none",
            "look-alike frames: highest (raw)": _both(imp, alike.max()) if alike.size else "none",
            "look-alikes above sigma": f"{int((alike >= sigma).sum())} of {alike.size}",
        })
    return pd.DataFrame(rows, columns=COLUMNS).set_index("target")


def _both(imp, score: float) -> str:
    return f"{score:.3f} ({float(imp.raw(score)):.3f})"
