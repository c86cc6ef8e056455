"""The paper's tables: rows of metrics rendered as DataFrames, Markdown and LaTeX.

Used by ``report``, ``bench``, ``similarity``, ``analysis`` and the CLI. A row is built
explicitly from what it comes from (``report_row`` for a report, ``tuning_row`` for a
tuning result), never guessed from a dict's keys; every row carries its sigma and where
that sigma came from. Undefined numbers are NaN in the DataFrame and "n/a" in the text,
never 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

# (metric key, column header, decimals): the paper's four first, then ours
TABLE_COLUMNS = [("match_pct", "%Match", 2), ("tm_pct", "TM", 2), ("cm_pct", "CM", 2), ("nm_pct", "NM", 2),
                 ("gm_pct", "GM", 2), ("om_pct", "OM", 2), ("target_recall", "Recall", 2),
                 ("auroc_target", "AUROC", 3), ("auroc_same", "AUROC-same", 3), ("first_match_precision", "FM-prec", 2)]
# the navigation estimate (``navigation``) in the paper's order, before the detection columns as in its Table 2,
# then the share of episodes where the agent never stopped; only where the frame-set has geometry
NAVIGATION_COLUMNS = [("sr", "SR", 2), ("spl", "SPL", 2), ("ce", "CE", 2), ("d2g", "D2G", 2), ("steps", "Steps", 1),
                      ("not_found_pct", "Not found", 2)]
# what a stop policy other than PIN's rule committed to (``commits``): % of episodes committed to the target and to a
# look-alike, % still looking when the walk ended, and the frames looked at before committing; only where a row has
# them
COMMIT_COLUMNS = [("commit_target_pct", "Commit T", 2), ("commit_lookalike_pct", "Commit C", 2),
                  ("still_looking_pct", "Still looking", 2), ("frames_looked_at", "Looked", 1)]
CATEGORY_COLUMNS = [("n_episodes", "Episodes", 0), *TABLE_COLUMNS]
ALL_COLUMNS = [*NAVIGATION_COLUMNS, *COMMIT_COLUMNS, *CATEGORY_COLUMNS]
SIGMA_FROM = "sigma from"


@dataclass(frozen=True)
class Row:
    """One matcher's line of the paper's table."""

    name: str
    sigma: float
    sigma_source: str
    metrics: dict


def report_row(result: dict) -> Row:
    """The row of a ``report`` / ``evaluate`` result (its metrics at the reported sigma); a stop policy other than
    PIN's rule is named after the matcher."""
    policy = result.get("policy", "1-of-1")
    name = result["matcher_id"] if policy == "1-of-1" else f"{result['matcher_id']} {policy}"
    return Row(name, result["sigma"], result["sigma_source"], result["metrics"])


def tuning_row(result: dict) -> Row:
    """The row of a ``tune`` result: the metrics on the tuning split at the chosen sigma."""
    return Row(result["matcher_id"], result["sigma"], f"tuned: {result['objective']} on {result['split']}",
               result["metrics_at_sigma"])


def side_by_side(rows: Sequence[Row]) -> pd.DataFrame:
    """The paper's table: one row per matcher (sigma, where it came from, then the metrics), NaN = undefined; the
    navigation columns first where any row has them (a frame-set with geometry), then what a stop policy committed
    to where any row has it."""
    columns = [*(NAVIGATION_COLUMNS if any("sr" in r.metrics for r in rows) else []),
               *(COMMIT_COLUMNS if any("commit_target_pct" in r.metrics for r in rows) else []), *TABLE_COLUMNS]
    data = {}
    for r in rows:
        data[r.name] = {"sigma": r.sigma, SIGMA_FROM: r.sigma_source,
                        **{header: _nan(r.metrics.get(key)) for key, header, _ in columns}}
    return pd.DataFrame.from_dict(data, orient="index").rename_axis("Matcher")


def sigma_caption(rows: Sequence[Row], split: str) -> str:
    """A caption that says which sigma every row is at: one phrase when they share a source."""
    sources = sorted({r.sigma_source for r in rows})
    said = f"sigma {sources[0]}" if len(sources) == 1 else "sigma per row, source in the 'sigma from' column"
    what = "Navigation (SR to Not found: estimated from the recorded walks, docs/metrics.md) and detection" \
        if any("sr" in r.metrics for r in rows) else "Detection"
    return f"{what} on the {split} split; {said}."


def category_table(categories: pd.DataFrame) -> pd.DataFrame:
    """The per-category metrics in the table layout (rows = target categories)."""
    return pd.DataFrame({header: categories[key] for key, header, _ in CATEGORY_COLUMNS}).rename_axis("Category")


def report_tables(result: dict, categories: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A report's two tables: its row of the paper's table and its per-category table."""
    return side_by_side([report_row(result)]), category_table(categories)


def _nan(value: float | None) -> float:
    return math.nan if value is None else float(value)


def _decimals(header: str) -> int | None:
    return next((d for _, h, d in ALL_COLUMNS if h == header), None)


def format_value(value: object, decimals: int | None) -> str:
    """Fixed decimals (None: shortest form, for sigma); text as is; undefined is "n/a", never 0."""
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, (float, np.floating)) and math.isnan(value)):
        return "n/a"
    if decimals is None:
        return f"{float(value):g}"
    return f"{float(value):.{decimals}f}"


def text_rows(df: pd.DataFrame) -> list[list[str]]:
    return [[str(index)] + [format_value(v, _decimals(c)) for c, v in row.items()] for index, row in df.iterrows()]


def _md(text: object) -> str:
    """A cell that cannot end its column or row: ``|`` escaped, line breaks as spaces."""
    return " ".join(str(text).replace("\\", "\\\\").replace("|", "\\|").splitlines())


def markdown_table(df: pd.DataFrame) -> str:
    header = [df.index.name or "", *df.columns]
    align = ["---:" if pd.api.types.is_numeric_dtype(df[c]) else "---" for c in df.columns]
    lines = ["| " + " | ".join(_md(h) for h in header) + " |", "|" + "|".join(["---", *align]) + "|"]
    lines += ["| " + " | ".join(_md(c) for c in r) + " |" for r in text_rows(df)]
    return "\n".join(lines)


def _tex(text: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("_", r"\_"), ("#", r"\#")):
        text = text.replace(a, b)
    return text


def latex_table(df: pd.DataFrame, caption: str = "") -> str:
    header = [df.index.name or "", *df.columns]
    cols = "".join("r" if pd.api.types.is_numeric_dtype(df[c]) else "l" for c in df.columns)
    lines = [r"\begin{table}[t]", r"\centering", r"\begin{tabular}{l" + cols + "}", r"\toprule",
             " & ".join(_tex(h) for h in header) + r" \\", r"\midrule"]
    lines += [" & ".join(_tex(c) for c in r) + r" \\" for r in text_rows(df)]
    lines += [r"\bottomrule", r"\end{tabular}"]
    if caption:
        lines.append(r"\caption{" + _tex(caption) + "}")
    lines.append(r"\end{table}")
    return "\n".join(lines)
