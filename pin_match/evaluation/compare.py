"""Two matchers on the same frames and split: the paired table, McNemar's test, and the page of their disagreements.

Writes ``compare.csv``, ``compare.md`` and ``compare.html`` (images in ``compare_files/``)
into one folder; the numbers come from ``paired``, the pictures from ``gallery``.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.evaluation import html
from pin_match.evaluation.evaluator import split_frames
from pin_match.evaluation.gallery import draw_frame, frame_points, frame_roles, thumbnail
from pin_match.evaluation.labels import frame_labels
from pin_match.evaluation.paired import disagreements, first_match_outcomes, mcnemar, paired_comparison
from pin_match.evaluation.sigma import SigmaChoice
from pin_match.evaluation.tables import markdown_table
from pin_match.scoring.table import ScoreTable

FILES = ("compare.csv", "compare.md", "compare.html")


def compare(table_a: ScoreTable, table_b: ScoreTable, fs: FrameSet, sigma_a: SigmaChoice, sigma_b: SigmaChoice,
            out_dir: str | Path, *, split: str | None = "val", labels: pd.DataFrame | None = None,
            n_boot: int = 1000, seed: int = 0, cap: int = 12) -> tuple[pd.DataFrame, dict]:
    """Write the comparison folder; returns the paired table (rows = metrics) and McNemar's result.

    ``labels``: ``frame_labels(fs)`` when the caller already has them (built here once otherwise).
    """
    names = (table_a.matcher_id, table_b.matcher_id)
    labels = frame_labels(fs) if labels is None else labels
    scored_a, scored_b = (split_frames(t, fs, split, labels) for t in (table_a, table_b))
    clusters = dict(zip(fs.episodes.episode_id, fs.episodes.target_object_id))
    paired = paired_comparison(scored_a, scored_b, sigma_a.value, sigma_b.value, clusters=clusters, names=names,
                               n_boot=n_boot, seed=seed)
    test = mcnemar(*first_match_outcomes(scored_a, scored_b, sigma_a.value, sigma_b.value))
    out = Path(out_dir)
    atomic.write_text(out / FILES[0], paired.to_csv())
    summary = summary_lines(paired, test, names, sigma_a, sigma_b, split)
    atomic.write_text(out / FILES[1], "\n\n".join([f"# {names[1]} vs {names[0]}", *summary,
                                                   markdown_table(paired.round(3))]) + "\n")
    gaps = disagreements(scored_a, scored_b, sigma_a.value, sigma_b.value, cap)
    write_compare_page(out / FILES[2], fs, (table_a, table_b), (sigma_a.value, sigma_b.value), paired, summary, gaps)
    return paired, test


def compare_bench(run_dir: str | Path, frameset: FrameSet | str | Path | None = None, split: str = "val",
                  n_boot: int = 1000) -> list[Path]:
    """Every matcher of a bench folder against the first, into ``run_dir/compare/<B>_vs_<A>/``; the pages."""
    from pin_match.evaluation.analysis import load_bench

    run = load_bench(run_dir, frameset)
    first, *others = run.matchers
    choice = {m: SigmaChoice(run.sigmas[m], run.reports[m]["sigma_source"], run.reports[m]["sigma_detail"])
              for m in run.matchers}
    pages = []
    for other in others:
        out = Path(run_dir) / "compare" / f"{other}_vs_{first}"
        compare(run.tables[first], run.tables[other], run.frameset, choice[first], choice[other], out, split=split,
                labels=run.labels, n_boot=n_boot)
        pages.append(out / FILES[2])
    return pages


def summary_lines(paired: pd.DataFrame, test: dict, names: tuple[str, str], sigma_a: SigmaChoice,
                  sigma_b: SigmaChoice, split: str | None) -> list[str]:
    a = paired.attrs
    return [f"Split {split or 'all'}; {names[0]} at sigma {sigma_a.value:g} ({sigma_a.source}), {names[1]} at sigma "
            f"{sigma_b.value:g} ({sigma_b.source}).",
            f"Differences are {names[1]} minus {names[0]} on the same {a['n_episodes']} episodes; "
            f"{a['level']:.0%} paired bootstrap intervals, {a['n_boot']} resamples of the {a['n_units']} target "
            "instances (all episodes of a drawn instance together). Gaps under 2 points are noise.",
            f"McNemar (first match is the target, per episode): only {names[0]} right in {test['only_a']}, only "
            f"{names[1]} right in {test['only_b']}, both {test['both']}, neither {test['neither']}; exact two-sided "
            f"p = {test['p_value']:.3g}."]


def drawn(fs: FrameSet, table: ScoreTable, frame_id: str, sigma: float, assets: html.Assets) -> str:
    """The frame with one matcher's points at its sigma, as an image tag."""
    src = assets.add((table.matcher_id, frame_id),
                     lambda: thumbnail(draw_frame(fs, frame_id, frame_points(table, frame_id, sigma)), 240))
    return html.image(src, f"{frame_id} with the points of {table.matcher_id}")


def write_compare_page(path: Path, fs: FrameSet, tables: tuple[ScoreTable, ScoreTable], sigmas: tuple[float, float],
                       paired: pd.DataFrame, summary: list[str], gaps: pd.DataFrame) -> Path:
    assets = html.Assets(path, "compare_files")
    gaps = gaps.assign(role=frame_roles(gaps))
    figures = []
    for _, f in gaps.iterrows():
        images = [drawn(fs, t, f.frame_id, s, assets) for t, s in zip(tables, sigmas)]
        lines = [f"frame {f.frame_id} ({f.role}), episode {f.episode_id}",
                 *(f"{t.matcher_id}: score {score:.4g} ({'above' if score >= s else 'below'} sigma)"
                   for t, s, score in zip(tables, sigmas, (f.score_a, f.score_b)))]
        figures.append(html.figure(images, lines))
    parts = [*(html.paragraph(line) for line in summary), html.table(paired.round(3)),
             html.heading("Frames where the two disagree most"),
             html.paragraph(f"One matcher accepts the frame at its sigma and the other rejects it, the largest gap "
                            f"in score percentile first; left {tables[0].matcher_id}, right {tables[1].matcher_id}; "
                            f"{len(gaps)} shown (capped).", "note"), html.gallery(figures)]
    return html.write_page(path, f"{tables[1].matcher_id} vs {tables[0].matcher_id}", parts)
