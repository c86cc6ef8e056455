"""One matcher's results at one sigma, written as the paper lays them out, plus curves and plots.

``report`` writes metrics.json (every number, with confidence intervals and provenance),
per_category.csv, metrics.md and metrics.tex (the paper's table: rows = matchers,
columns %Match / TM / CM / NM, then ours), and PNG plots. ``side_by_side`` puts several
``report`` results into one such table (``bench`` uses it). Undefined numbers are None
in JSON, NaN in CSV and "n/a" in the tables.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.errors import PinMatchError
from pin_match.frameset import FrameSet
from pin_match.labels import frame_labels, localisation_hits, scored_frames
from pin_match.metrics import CLASSES, bootstrap_ci, detection_metrics, frame_arrays, localisation_metrics, per_category
from pin_match.scoretable import ScoreTable
from pin_match.sweep import sweep
from pin_match.tuning import load_threshold

# (metric key, column header, decimals): the paper's four first, then ours
TABLE_COLUMNS = [("match_pct", "%Match", 2), ("tm_pct", "TM", 2), ("cm_pct", "CM", 2), ("nm_pct", "NM", 2),
                 ("gm_pct", "GM", 2), ("om_pct", "OM", 2), ("target_recall", "Recall", 2),
                 ("auroc_target", "AUROC", 3), ("first_match_precision", "FM-prec", 2)]
CATEGORY_COLUMNS = [("n_episodes", "Episodes", 0), *TABLE_COLUMNS]
MAX_PLOT_POINTS = 2000


class ReportError(PinMatchError, ValueError):
    """Scores, frame-set and threshold do not belong together."""


def resolve_sigma(table: ScoreTable, sigma: float | None = None,
                  thresholds: str | Path | None = None) -> tuple[float, str]:
    """The threshold to report at and where it came from: explicit, a thresholds file, or the matcher's default."""
    if sigma is not None and thresholds is not None:
        raise ReportError("give either a threshold or a thresholds file, not both")
    if sigma is not None:
        return float(sigma), "explicit"
    if thresholds is not None:
        return load_threshold(thresholds, table.matcher_id), str(thresholds)
    if table.meta.get("default_sigma") is not None:
        return float(table.meta["default_sigma"]), "matcher default"
    raise ReportError(f"score table of {table.matcher_id} names no default sigma: "
                      "pass a threshold or a thresholds file")


def evaluate(table: ScoreTable, fs: FrameSet, sigma: float, split: str | None = "val", *, n_boot: int = 1000,
             seed: int = 0) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """Metrics (with CIs and localisation), the per-category table and the scored frames of one split."""
    fingerprint = table.meta.get("frameset_fingerprint")
    if fingerprint is not None and fingerprint != fs.fingerprint:
        raise ReportError(f"score table of {table.matcher_id} was computed on frame-set {fingerprint}, "
                          f"not on {fs.root} ({fs.fingerprint})")
    scored = scored_frames(frame_labels(fs), table)
    if split not in (None, "all"):
        scored = scored[scored.split == split].reset_index(drop=True)
    if scored.empty:
        raise ReportError(f"score table of {table.matcher_id} has no frames of split {split!r} "
                          f"(it has {sorted(set(table.frames.split))})")
    metrics = detection_metrics(scored, sigma)
    hits = localisation_hits(fs, table_subset(table, scored.frame_id), sigma)
    metrics.update(localisation_metrics(hits))
    result = dict(matcher=table.matcher, matcher_id=table.matcher_id, config_hash=table.meta.get("config_hash"),
                  modality=table.meta.get("modality"), frameset_fingerprint=fs.fingerprint, split=split or "all",
                  sigma=float(sigma), metrics=metrics,
                  ci95=bootstrap_ci(scored, sigma, n_boot=n_boot, seed=seed), n_bootstrap=n_boot,
                  date=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))
    return result, per_category(scored, sigma), scored


def table_subset(table: ScoreTable, frame_ids: pd.Series) -> ScoreTable:
    return ScoreTable(table.frames[table.frames.frame_id.isin(frame_ids)].reset_index(drop=True), table.meta)


def report(table: ScoreTable, fs: FrameSet, out_dir: str | Path, *, sigma: float | None = None,
           thresholds: str | Path | None = None, split: str | None = "val", n_boot: int = 1000,
           seed: int = 0, sigma_source: str | None = None) -> dict:
    """Evaluate at one sigma and write the report folder; returns metrics.json's content plus ``files``."""
    sigma, source = resolve_sigma(table, sigma, thresholds)
    result, categories, scored = evaluate(table, fs, sigma, split, n_boot=n_boot, seed=seed)
    result["sigma_source"] = sigma_source or source
    out = Path(out_dir)
    files = [out / name for name in ("metrics.json", "per_category.csv", "metrics.md", "metrics.tex",
                                     "sigma_curves.png", "score_distributions.png", "per_category.png")]
    atomic.write_json(files[0], result)
    atomic.write_text(files[1], categories.to_csv(index_label="category"))
    overall = side_by_side([result])
    per_cat = category_table(categories)
    title = f"{table.matcher_id}, split {result['split']}, sigma = {sigma:g}"
    atomic.write_text(files[2], f"# {title}\n\n{markdown_table(overall)}\n\n## Per target category\n\n"
                                f"{markdown_table(per_cat)}\n")
    atomic.write_text(files[3], latex_table(overall, caption=f"{title}.") + "\n"
                      + latex_table(per_cat, caption=f"{title}, per target category.") + "\n")
    plot_sigma_curves(sweep(scored), sigma, files[4], title)
    plot_score_distributions(scored, sigma, files[5], title)
    plot_per_category(categories, files[6], title)
    return {**result, "files": [str(f) for f in files]}


# --------------------------------------------------------------------------- tables
def side_by_side(results: Sequence[dict]) -> pd.DataFrame:
    """Several ``report`` (or ``tune``) results as the paper's table: one row per matcher, NaN = undefined."""
    rows = {}
    for r in results:
        m = r["metrics"] if "metrics" in r else r["metrics_at_sigma"]  # a report or a tuning result
        row = {"sigma": r["sigma"]}
        row.update({header: _nan(m.get(key)) for key, header, _ in TABLE_COLUMNS})
        rows[r.get("matcher_id") or r["matcher"]] = row
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("Matcher")


def category_table(categories: pd.DataFrame) -> pd.DataFrame:
    """The per-category metrics in the table layout (rows = target categories)."""
    return pd.DataFrame({header: categories[key] for key, header, _ in CATEGORY_COLUMNS}).rename_axis("Category")


def _nan(value: float | None) -> float:
    return math.nan if value is None else float(value)


def _decimals(header: str) -> int | None:
    return next((d for _, h, d in CATEGORY_COLUMNS if h == header), None)


def format_value(value: object, decimals: int | None) -> str:
    """Fixed decimals (None: shortest form, for sigma); undefined is "n/a", never 0."""
    if value is None or (isinstance(value, (float, np.floating)) and math.isnan(value)):
        return "n/a"
    if decimals is None:
        return f"{float(value):g}"
    return f"{float(value):.{decimals}f}"


def _rows(df: pd.DataFrame) -> list[list[str]]:
    return [[str(index)] + [format_value(v, _decimals(c)) for c, v in row.items()] for index, row in df.iterrows()]


def markdown_table(df: pd.DataFrame) -> str:
    header = [df.index.name or "", *df.columns]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] + ["---:"] * len(df.columns)) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in _rows(df)]
    return "\n".join(lines)


def _tex(text: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("_", r"\_"), ("#", r"\#")):
        text = text.replace(a, b)
    return text


def latex_table(df: pd.DataFrame, caption: str = "") -> str:
    header = [df.index.name or "", *df.columns]
    lines = [r"\begin{table}[t]", r"\centering", r"\begin{tabular}{l" + "r" * len(df.columns) + "}", r"\toprule",
             " & ".join(_tex(h) for h in header) + r" \\", r"\midrule"]
    lines += [" & ".join(_tex(c) for c in r) + r" \\" for r in _rows(df)]
    lines += [r"\bottomrule", r"\end{tabular}"]
    if caption:
        lines.append(r"\caption{" + _tex(caption) + "}")
    lines.append(r"\end{table}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- plots
def _figure(path: Path, draw) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    try:
        draw(ax)
        fig.tight_layout()
        with atomic.atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=120)
    finally:
        plt.close(fig)


def plot_sigma_curves(curve: pd.DataFrame, sigma: float, path: str | Path, title: str = "") -> None:
    """TM / CM / NM (% of matched frames) and %Match (% of episodes) against sigma."""
    step = max(1, len(curve) // MAX_PLOT_POINTS)
    c = curve.iloc[::step]

    def draw(ax) -> None:
        for key, label in (("tm_pct", "TM"), ("cm_pct", "CM"), ("nm_pct", "NM"), ("match_pct", "%Match")):
            # a row holds for sigma in (previous distinct score, its score]: steps drawn "pre"
            ax.plot(c["sigma"], c[key], label=label, linestyle="--" if key == "match_pct" else "-",
                    drawstyle="steps-pre")
        ax.axvline(sigma, color="k", linewidth=0.8, label=f"sigma = {sigma:g}")
        ax.set(xlabel="sigma", ylabel="%", ylim=(-2, 102), title=title)
        ax.legend(fontsize=8)

    _figure(Path(path), draw)


def plot_score_distributions(scored: pd.DataFrame, sigma: float, path: str | Path, title: str = "") -> None:
    """Score histograms of frames by what they show (target, same-category, other distractor, nothing)."""
    arr = frame_arrays(scored)
    bins = np.linspace(arr.score.min(), arr.score.max(), 50) if arr.score.size and np.ptp(arr.score) > 0 else 10
    names = dict(zip(CLASSES, ("target", "same category", "other distractor", "nothing")))

    def draw(ax) -> None:
        for code, cls in enumerate(CLASSES):
            s = arr.score[arr.cls == code]
            if s.size:
                ax.hist(s, bins=bins, density=True, histtype="step", label=f"{names[cls]} ({s.size})")
        ax.axvline(sigma, color="k", linewidth=0.8)
        ax.set(xlabel="score", ylabel="density", title=title)
        ax.legend(fontsize=8)

    _figure(Path(path), draw)


def plot_per_category(categories: pd.DataFrame, path: str | Path, title: str = "") -> None:
    """Stacked TM / CM / NM bars per target category (undefined categories left empty)."""

    def draw(ax) -> None:
        x = np.arange(len(categories))
        bottom = np.zeros(len(categories))
        for key, label in (("tm_pct", "TM"), ("cm_pct", "CM"), ("nm_pct", "NM")):
            values = categories[key].fillna(0.0).to_numpy()
            ax.bar(x, values, bottom=bottom, label=label)
            bottom += values
        ax.plot(x, categories["match_pct"], "k^", label="%Match")
        ax.set_xticks(x, categories.index, rotation=45, ha="right")
        ax.set(ylabel="%", ylim=(0, 105), title=title)
        ax.legend(fontsize=8)

    _figure(Path(path), draw)
