"""The report's figures: sigma curves, score distributions and per-category bars (PNG, written atomically)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.evaluation.core.labels import CLASSES
from pin_match.evaluation.core.metrics import FrameArrays
from pin_match.evaluation.core.stop import UPPER_BOUND

MAX_PLOT_POINTS = 2000
TITLE_WIDTH = 0.96  # share of the figure's width a title line may take
# where a title may break, most readable first: between clauses (after a comma, before a parenthesis: the
# sigma's provenance "(tuned: first-match on train)" stays one line), between words, inside a word (a long id)
TITLE_BREAKS = (r"(?<=,) | (?=\()", " ", "")


def _figure(path: Path, title: str, draw) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    try:
        draw(ax)
        if title:
            _fit_title(fig, title)
        fig.tight_layout()
        with atomic.atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=120)
    finally:
        plt.close(fig)


def _fit_title(fig, title: str) -> None:
    """The title over the whole figure, broken into lines that fit its width, so no part of it is cut off.

    Report titles end with where sigma came from, the part a reader must not lose. Over the figure,
    not the axes: an axes title is centred on the axes, which the y label shifts right.
    """
    text = fig.suptitle(title)
    renderer = fig.canvas.get_renderer()
    limit = TITLE_WIDTH * fig.bbox.width

    def fits(line: str) -> bool:
        text.set_text(line)
        return text.get_window_extent(renderer).width <= limit

    text.set_text("\n".join(_lines(title, fits)))


def _lines(text: str, fits, level: int = 0) -> list[str]:
    """Greedy line filling at ``TITLE_BREAKS[level]``; a piece too wide alone is broken at the next level."""
    if level == len(TITLE_BREAKS) or fits(text):
        return [text]
    pieces = re.split(TITLE_BREAKS[level], text) if TITLE_BREAKS[level] else list(text)
    joint = " " if TITLE_BREAKS[level] else ""
    lines: list[str] = []
    current = ""
    for piece in pieces:
        candidate = f"{current}{joint}{piece}" if current else piece
        if fits(candidate):
            current = candidate
            continue
        if current:
            lines.append(current)
        *full, current = _lines(piece, fits, level + 1)
        lines += full
    return [*lines, current]


def plot_sigma_curves(curve: pd.DataFrame, sigma: float, path: str | Path, title: str = "") -> None:
    """TM / CM / NM (% of matched frames) and %Match (% of episodes) against sigma."""
    step = max(1, len(curve) // MAX_PLOT_POINTS)
    _curves(curve.iloc[::step], sigma, (("tm_pct", "TM"), ("cm_pct", "CM"), ("nm_pct", "NM"), ("match_pct", "%Match")),
            "%", Path(path), title)


def plot_navigation_curves(curve: pd.DataFrame, sigma: float, path: str | Path, title: str = "") -> None:
    """SR, SPL and CE (% of episodes) and the share not found against sigma (``navigation.navigation_sweep``)."""
    _curves(curve, sigma, (("sr", "SR"), ("spl", "SPL"), ("ce", "CE"), ("not_found_pct", "not found")),
            "% of episodes", Path(path), title)


def _curves(curve: pd.DataFrame, sigma: float, series: tuple[tuple[str, str], ...], ylabel: str, path: Path,
            title: str) -> None:
    """Percentages against sigma, the last series dashed, sigma marked."""

    def draw(ax) -> None:
        for key, label in series:
            # a row holds for sigma in (previous distinct score, its score]: steps drawn "pre"
            ax.plot(curve["sigma"], curve[key], label=label, linestyle="--" if key == series[-1][0] else "-",
                    drawstyle="steps-pre")
        ax.axvline(sigma, color="k", linewidth=0.8, label=f"sigma = {sigma:g}")
        ax.set(xlabel="sigma", ylabel=ylabel, ylim=(-2, 102))
        ax.legend(fontsize=8)

    _figure(path, title, draw)


def plot_score_distributions(arr: FrameArrays, sigma: float, path: str | Path, title: str = "") -> None:
    """Score histograms of frames by what they show (target, same-category, other distractor, nothing)."""
    bins = np.linspace(arr.score.min(), arr.score.max(), 50) if arr.score.size and np.ptp(arr.score) > 0 else 10
    names = dict(zip(CLASSES, ("target", "same category", "other distractor", "nothing")))

    def draw(ax) -> None:
        for code, cls in enumerate(CLASSES):
            s = arr.score[arr.cls == code]
            if s.size:
                ax.hist(s, bins=bins, density=True, histtype="step", label=f"{names[cls]} ({s.size})")
        ax.axvline(sigma, color="k", linewidth=0.8)
        ax.set(xlabel="score", ylabel="density")
        ax.legend(fontsize=8)

    _figure(Path(path), title, draw)


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
        ax.set(ylabel="%", ylim=(0, 105))
        ax.legend(fontsize=8)

    _figure(Path(path), title, draw)


def plot_trade(rows: pd.DataFrame, path: str | Path, title: str = "") -> None:
    """``flows.trade``'s rows: per matcher, SR, CE, SPL and Steps against the look-further window (where the frame-set
    has geometry; else the shares committed to the target and to a look-alike and the frames looked at), the rest of
    the walk drawn apart at the right as the upper bound it is. Only plain windows (``look:W``) are drawn; the other
    policies' rows stay in trade.csv."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = rows[rows["policy"].str.fullmatch(rf"look:(\d+|rest{re.escape(UPPER_BOUND)})")]
    walks = "sr" in rows and rows["sr"].notna().any()
    panels = (("sr", "SR %"), ("ce", "CE %"), ("spl", "SPL %"), ("steps", "Steps")) if walks else \
        (("commit_target_pct", "committed to the target %"), ("commit_lookalike_pct", "committed to a look-alike %"),
         ("frames_looked_at", "frames looked at"))
    windows = sorted(rows["window"].dropna().unique())
    rest = (max(windows) if windows else 0) * 1.25 + 5
    fig, axes = plt.subplots(1, len(panels), figsize=(3.6 * len(panels), 3.6), squeeze=False)
    try:
        for ax, (key, label) in zip(axes[0], panels):
            for name, group in rows.groupby("matcher", sort=False):
                lines = group[group["window"].notna()].sort_values("window")
                drawn = ax.plot(lines["window"], lines[key], marker="o", label=name)
                bound = group[group["upper_bound"]]
                ax.plot([rest] * len(bound), bound[key], marker="*", linestyle="none", color=drawn[0].get_color())
            ticks = [*windows, rest]
            ax.set_xticks(ticks, [f"{w:g}" for w in windows] + ["rest\n(upper bound)"])
            ax.set(xlabel="frames looked on after the first firing", ylabel=label)
        axes[0][0].legend(fontsize=8)
        if title:
            _fit_title(fig, title)
        fig.tight_layout()
        with atomic.atomic_path(Path(path)) as tmp:
            fig.savefig(tmp, format="png", dpi=120)
    finally:
        plt.close(fig)
