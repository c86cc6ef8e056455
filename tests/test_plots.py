"""The report's figures keep every title and legend inside the picture, even with the longest title a report makes."""

from __future__ import annotations

import re

import matplotlib
import pandas as pd
import pytest

from pin_match.contract.registry import available_names
from pin_match.evaluation import Bootstrap, EvalContext
from pin_match.evaluation.core.sigma import SigmaChoice
from pin_match.evaluation.core.tuning import OBJECTIVES
from pin_match.evaluation.flows.report import report
from pin_match.scoring.table import ScoreTable

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.legend import Legend  # noqa: E402
from matplotlib.text import Text  # noqa: E402

# the longest provenance sigma.load_threshold writes: "tuned: <objective> on <split>" (splits: train, val)
LONGEST_SOURCE = f"tuned: {max(OBJECTIVES, key=len)} on train"
# a sigma whose ":g" form is as long as ":g" gets (sign, 6 digits, exponent)
LONGEST_SIGMA = -1.23457e-05
MATCHER_IDS = (f"{max(available_names(), key=len)}@0123456789ab",  # the longest shipped matcher
               "a-plug-in-matcher-from-another-package-with-a-descriptive-name@0123456789ab")  # no space to break at
PLOTS = ("sigma_curves.png", "score_distributions.png", "per_category.png")


def px(box) -> tuple[float, ...]:
    return tuple(round(float(v), 1) for v in box.extents)


def squash(text: str) -> str:
    return re.sub(r"\s", "", text)


def scored_table(fs, tmp_path, matcher_id: str) -> ScoreTable:
    """Every frame of the tiny frame-set scored: the target highest, a spread below it (steps: see conftest)."""
    step_scores = (0.9, 0.6, 0.3, 0.1)
    rows = [dict(frame_id=f.frame_id, episode_id=f.episode_id, step=int(f.step), split=f.split,
                 score=step_scores[int(f.step)], crop_scores=[step_scores[int(f.step)]], points_x=[148.0],
                 points_y=[348.0], point_scores=[step_scores[int(f.step)]], view=-1) for f in fs.frames.itertuples()]
    meta = dict(matcher=matcher_id.split("@")[0], matcher_id=matcher_id, config_hash=matcher_id.split("@")[1],
                frameset_fingerprint=fs.fingerprint, default_sigma=0.5, modality="visual")
    ScoreTable(pd.DataFrame(rows), meta).write(tmp_path / "scores.parquet")
    return ScoreTable.read(tmp_path / "scores.parquet")


@pytest.mark.parametrize("matcher_id", MATCHER_IDS)
def test_report_plots_keep_titles_and_legends_inside_the_figure(tiny_frameset, tmp_path, monkeypatch, matcher_id):
    figures = []
    monkeypatch.setattr(plt, "close", figures.append)  # keep each figure open after it is saved, to measure it
    choice = SigmaChoice(LONGEST_SIGMA, LONGEST_SOURCE, "tuned, read from thresholds.json")
    out = tmp_path / "report"
    report(scored_table(tiny_frameset, tmp_path, matcher_id), EvalContext(tiny_frameset, Bootstrap(n_boot=10)), out,
           sigma=choice)
    title = f"{matcher_id}, split val, sigma = {LONGEST_SIGMA:g} ({LONGEST_SOURCE})"
    assert len(figures) == len(PLOTS) and all((out / name).stat().st_size > 0 for name in PLOTS)
    try:
        for name, fig in zip(PLOTS, figures):
            fig.canvas.draw()
            renderer = fig.canvas.get_renderer()
            inside = fig.bbox.padded(0.5)  # half a pixel for rounding
            # the whole title, provenance included, is drawn: wrapped maybe, never cut or shortened
            titles = [t for t in fig.findobj(Text) if t.get_visible() and squash(t.get_text()) == squash(title)]
            assert len(titles) == 1, f"{name}: no text shows the title {title!r}"
            legends = fig.findobj(Legend)
            assert legends, f"{name} has no legend"
            for artist in [*titles, *legends]:
                box = artist.get_window_extent(renderer)
                assert inside.contains(box.x0, box.y0) and inside.contains(box.x1, box.y1), \
                    f"{name}: {type(artist).__name__} at {px(box)} leaves the figure {px(fig.bbox)}"
            for ax in fig.axes:  # tick labels and axis labels too
                box = ax.get_tightbbox(renderer)
                assert inside.contains(box.x0, box.y0) and inside.contains(box.x1, box.y1), \
                    f"{name}: axes decorations at {px(box)} leave the figure {px(fig.bbox)}"
    finally:
        monkeypatch.undo()
        plt.close("all")


def test_titles_break_between_clauses_first_then_words_then_inside_a_word():
    from pin_match.evaluation.pages.plots import _lines

    def fits(line: str) -> bool:
        return len(line) <= 30

    assert _lines("stub@abc, split val, sigma = 0.5 (tuned: first-match on train)", fits) == \
        ["stub@abc, split val,", "sigma = 0.5", "(tuned: first-match on train)"]
    assert _lines("sigma = 0.5 (tuned: a-very-long-objective-name on train)", fits) == \
        ["sigma = 0.5", "(tuned:", "a-very-long-objective-name on", "train)"]
    assert _lines("x" * 35 + ", split val", fits) == ["x" * 30, "xxxxx, split val"]
    assert _lines("short title", fits) == ["short title"]
