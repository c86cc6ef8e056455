"""report.html and its galleries on the tiny hand-made frame-set, where the right content is known in advance."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from pin_match.evaluation import Bootstrap, EvalContext
from pin_match.evaluation.core.labels import frame_labels, scored_frames
from pin_match.evaluation.flows.report import report
from pin_match.evaluation.pages.gallery import (
    OUTLINE_RGB,
    POINT_RGB,
    draw_frame,
    frame_points,
    section_figure,
    sections,
)
from pin_match.scoring.table import ScoreTable

# per episode, steps 0..3 show: the target, a same-category look-alike, an other-category object, nothing
SCORES = {"ep_train": [0.9, 0.2, 0.1, 0.1], "ep_val": [0.3, 0.6, 0.95, 0.1]}
PLANTED = "ep_val_0002"   # the highest-scoring frame without the target: an other-category object
PLANTED_POINT = (50.0, 60.0)
SIGMA = 0.5


# the views the best boxes matched where a matcher names them: the val target frame (a miss) from behind, the
# look-alike (a false alarm) frontal, the other object (the planted false alarm) from the top, the empty frame none
VIEWS = {"ep_val_0000": 1, "ep_val_0001": 0, PLANTED: 2, "ep_val_0003": -1}


def make_table(fs, views: dict[str, int] | None = None) -> ScoreTable:
    rows = []
    for episode, scores in SCORES.items():
        for step, score in enumerate(scores):
            frame_id = f"{episode}_{step:04d}"
            x, y = PLANTED_POINT if frame_id == PLANTED else (148.0, 348.0)
            rows.append(dict(frame_id=frame_id, episode_id=episode, step=step, split=episode.split("_")[1],
                             score=score, crop_scores=[score], points_x=[x], points_y=[y], point_scores=[score],
                             view=(views or {}).get(frame_id, -1)))
    meta = dict(matcher="stub", matcher_id="stub@abc", config_hash="abc", config={"weights": "none.pt"},
                frameset_fingerprint=fs.fingerprint, default_sigma=SIGMA, modality="visual")
    return ScoreTable(pd.DataFrame(rows), meta)


@pytest.fixture(scope="module")
def tiny(tiny_frameset):
    return tiny_frameset, make_table(tiny_frameset)


def test_sections_hold_the_planted_frames(tiny):
    fs, table = tiny
    scored = scored_frames(frame_labels(fs), table)
    by_key = {s.key: s for s in sections(scored, SIGMA)}
    alarms = by_key["false_alarms"].frames
    assert alarms.frame_id.iloc[0] == PLANTED and alarms.role.iloc[0] == "other"
    assert "target" not in set(alarms.role) and by_key["false_alarms"].n_total == 6
    assert list(by_key["misses"].frames.frame_id) == ["ep_val_0000", "ep_train_0000"]
    first = by_key["first_match"].frames.set_index("episode_id")
    assert first.loc["ep_train", "role"] == "target"
    assert first.loc["ep_val", "role"] == "same-category look-alike"  # 0.6 at step 1 comes before the target
    capped = {s.key: s for s in sections(scored, SIGMA, cap=2)}["false_alarms"]
    assert len(capped.frames) == 2 and capped.n_total == 6


def test_points_are_drawn_where_the_stored_row_says(tiny):
    fs, table = tiny
    points = frame_points(table, PLANTED, SIGMA)
    np.testing.assert_allclose(points, [PLANTED_POINT])
    drawn = draw_frame(fs, PLANTED, points)
    x, y = map(int, PLANTED_POINT)
    assert tuple(drawn[y, x]) == POINT_RGB
    assert tuple(fs.image(PLANTED)[y, x]) != POINT_RGB
    assert len(frame_points(table, "ep_val_0003", SIGMA)) == 0  # below sigma: nothing to draw


def test_mask_outline_follows_the_target_mask(tiny):
    fs, _ = tiny
    drawn = draw_frame(fs, "ep_val_0000")
    green = np.all(drawn == OUTLINE_RGB["target"], axis=2)
    mask = fs.instance_mask("ep_val_0000") > 0
    ys, xs = np.nonzero(mask)
    gy, gx = np.nonzero(green)
    assert green.sum() > 50
    assert gy.min() >= ys.min() - 3 and gy.max() <= ys.max() + 3
    assert gx.min() >= xs.min() - 3 and gx.max() <= xs.max() + 3
    assert not green[ys.mean().astype(int), xs.mean().astype(int)]  # the inside is not painted


def test_report_writes_a_self_contained_page(tiny, tmp_path):
    fs, table = tiny
    result = report(table, EvalContext(fs, Bootstrap(n_boot=20)), tmp_path, sigma=SIGMA, split="val")
    page = tmp_path / "report.html"
    assert result["files"]["page"] == str(page)
    text = page.read_text(encoding="utf-8")
    for needle in ("stub@abc", fs.fingerprint, "none.pt", "sigma", "Per target category", "false alarms"):
        assert needle in text
    assert "http://" not in text and "https://" not in text and "<script" not in text
    sources = re.findall(r'<img src="([^"]+)"', text)
    assert len(sources) >= 3 + 4
    for src in sources:
        assert (tmp_path / src).is_file() and (tmp_path / src).stat().st_size > 0
    alarms = text[text.index('id="false_alarms"'):text.index('id="misses"')]
    assert alarms.index(f"frame {PLANTED}") < alarms.index("frame ep_val_0001")
    assert 'id="views"' not in text and "view: " not in text and "views" not in result["files"]  # none named


def _caption(text: str, frame_id: str, section: str) -> str:
    start = text.index(f'id="{section}"')
    start = text.index(f"frame {frame_id}<", start)
    return text[text.rindex("<figcaption>", 0, start):text.index("</figcaption>", start)]


def test_the_report_says_which_view_matched_where_the_matcher_names_views(tiny, tmp_path):
    """Issue 51.4: views.csv and its section with the counts of ``VIEWS`` at sigma 0.5, each gallery frame's caption
    with its view; a later report of a matcher naming none leaves neither behind."""
    fs, _ = tiny
    result = report(make_table(fs, VIEWS), EvalContext(fs, Bootstrap(n_boot=20)), tmp_path, sigma=SIGMA, split="val")
    views = pd.read_csv(result["files"]["views"], index_col="view")
    assert views[["tm_matched", "cm_matched", "target_frames"]].to_dict("index") == {
        "frontal": dict(tm_matched=0, cm_matched=1, target_frames=0),  # the look-alike at 0.6, matched
        "back": dict(tm_matched=0, cm_matched=0, target_frames=1),     # the target at 0.3, missed
        "top": dict(tm_matched=0, cm_matched=0, target_frames=0),      # the other object: neither TM nor CM
        "none named": dict(tm_matched=0, cm_matched=0, target_frames=0)}
    assert set(views.sigma) == {SIGMA} and set(views.sigma_source) == {"given"}
    text = (tmp_path / "report.html").read_text(encoding="utf-8")
    section = text[text.index('id="views"'):]
    section = section[:section.index("<h2")]
    assert "Which reference view matched" in section and "matched, look-alike only (CM)" in section
    assert "sigma 0.5 (given)" in section
    assert "view: back" in _caption(text, "ep_val_0000", "misses")
    assert "view: frontal" in _caption(text, "ep_val_0001", "false_alarms")
    assert "view: top" in _caption(text, PLANTED, "false_alarms")
    assert "view: " not in _caption(text, "ep_val_0003", "false_alarms")  # no view named for it
    again = report(make_table(fs), EvalContext(fs, Bootstrap(n_boot=20)), tmp_path, sigma=SIGMA, split="val")
    assert "views" not in again["files"] and not (tmp_path / "views.csv").exists()
    assert 'id="views"' not in (tmp_path / "report.html").read_text(encoding="utf-8")


def test_a_table_without_the_view_column_is_named_by_the_report(tiny, tmp_path):
    from pin_match.scoring.table import ScoreTableError

    fs, table = tiny
    bare = ScoreTable(table.frames.drop(columns="view"), table.meta)
    with pytest.raises(ScoreTableError, match=r"score table of stub@abc lacks columns \['view'\]"):
        report(bare, EvalContext(fs, Bootstrap(n_boot=20)), tmp_path, sigma=SIGMA, split="val")


def test_the_images_folder_starts_empty_and_one_that_cannot_be_emptied_is_named(tmp_path):
    """Issue 43.3b: a folder the page could not empty was once passed over, leaving the old images beside the page."""
    from pin_match.errors import PinMatchError
    from pin_match.evaluation.pages.html import Assets

    page = tmp_path / "report.html"
    Assets(page, "report_files")  # no earlier page: nothing to remove
    (tmp_path / "report_files").mkdir()
    (tmp_path / "report_files" / "0000.jpg").write_bytes(b"an earlier page's image")
    Assets(page, "report_files")
    assert not (tmp_path / "report_files").exists()
    (tmp_path / "report_files").write_text("a file where the images' folder goes")
    with pytest.raises(PinMatchError, match=r"cannot empty the images folder .*report_files"):
        Assets(page, "report_files")


def test_gallery_figure_for_notebooks(tiny):
    import matplotlib

    matplotlib.use("Agg")
    fs, table = tiny
    scored = scored_frames(frame_labels(fs), table)
    fig = section_figure(fs, table, sections(scored, SIGMA)[0], SIGMA, max_frames=2)
    assert len(fig.axes) == 8 and PLANTED in fig.axes[0].get_title() and "view" not in fig.axes[0].get_title()
    fig = section_figure(fs, make_table(fs, VIEWS), sections(scored, SIGMA)[0], SIGMA, max_frames=2)
    assert fig.axes[0].get_title().endswith("view: top")


def test_a_normalised_tables_report_shows_each_targets_cohort_beside_its_scores(tiny, tmp_path):
    """Issue 44.3: per target the scale and its closest cohort members, and the members beside a look-alike."""
    from pin_match import atomic
    from pin_match.contract.cohort import TargetCohort
    from pin_match.evaluation.pages.scales import scale_table, target_cohorts

    fs, stub = tiny
    folder = tmp_path / "cohort"
    atomic.write_image(folder / "m0.png", np.full((40, 40, 3), 200, np.uint8))  # m1.png is gone from this machine
    target = fs.episode("ep_val").target_object_id
    cohort = TargetCohort.of(str(folder), ["m2.png", "m0.png", "m1.png"], [0.1, 0.8, 0.6], k=2, min_std=0.25,
                             probability=True)
    meta = dict(stub.meta, score_scale="cohort-normalised: by hand", targets={target: cohort.as_notes()})
    table = ScoreTable(stub.frames, meta)
    assert target_cohorts(table) == {target: cohort}
    scored = EvalContext(fs).scored(table, "val")
    rows = scale_table(target_cohorts(table), scored, fs.episodes.set_index("episode_id").target_object_id, SIGMA)
    assert list(rows.index) == [target]  # the train episode's target is not in the val split
    (row,) = rows.to_dict("records")
    # 0.5 sits at the geometric mean of the odds of 0.8 and 0.6: sqrt(4 * 1.5) / (1 + sqrt(6))
    assert row["raw score at 0.5"] == pytest.approx(np.sqrt(6) / (1 + np.sqrt(6)), abs=1e-4)
    assert row["closest cohort members (raw score)"] == "m0.png 0.800, m1.png 0.600"
    raw = float(cohort.impostors.raw(0.6))
    assert row["look-alike frames: highest (raw)"] == f"0.600 ({raw:.3f})" and cohort.impostors.normalised(raw) \
        == pytest.approx(0.6)
    assert row["target frames: median (raw)"].startswith("0.300") and row["look-alikes above sigma"] == "1 of 1"

    report(table, EvalContext(fs, Bootstrap(n_boot=20)), tmp_path / "r", sigma=SIGMA, split="val")
    text = (tmp_path / "r" / "report.html").read_text(encoding="utf-8")
    assert "score scale" in text and "cohort-normalised: by hand" in text
    scales = text[text.index('id="scales"'):text.index('id="false_alarms"')]
    assert "m0.png 0.800, m1.png 0.600" in scales and scales.count('alt="cohort member m0.png') == 1
    assert 'alt="cohort member m1.png' not in text  # its image is not here: named, not drawn
    alarms = text[text.index('id="false_alarms"'):text.index('id="misses"')]
    lookalike = alarms[alarms.index("frame ep_val_0001"):]
    assert "closest cohort members: m0.png 0.800" in lookalike[:lookalike.index("</figure>")]
    other = alarms[alarms.index(f"frame {PLANTED}"):]
    assert "cohort" not in other[:other.index("</figure>")]  # another category's frame: no cohort strip
