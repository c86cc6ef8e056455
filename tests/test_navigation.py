"""The navigation estimate (SR, SPL, CE, D2G, Steps) on hand-built geometry, the renderer's own, and a PIN recording."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from conftest import make_view
from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.data.geometry import (
    AGENT_RADIUS,
    CameraModel,
    EpisodeGeometry,
    FloorMap,
    GeometryError,
    Pose,
    back_project,
)
from pin_match.data.writer import Frame, FrameSetWriter
from pin_match.evaluation import EvalContext, evaluate, report, tune
from pin_match.evaluation.core.navigation import (
    STAND_MARGIN,
    NavigationError,
    episodes_at,
    metrics_of,
    navigation_metrics,
    standing_point,
)
from pin_match.evaluation.core.sigma import SigmaChoice
from pin_match.evaluation.core.tables import report_row, side_by_side
from pin_match.evaluation.core.tuning import TuningError
from pin_match.scoring.table import ScoreTable

SIZE = 40  # square frames, HFOV 90 degrees: focal 20 px, the centre pixel (20, 20) looks straight ahead
CENTRE = (20.0, 20.0)
HEIGHT = 0.5  # the camera and every object's centre, metres above the floor: within reach of an agent standing by
TARGET, LOOKALIKE, OTHER = (3.0, 0.0, HEIGHT), (-3.0, 3.0, HEIGHT), (-6.0, 0.0, HEIGHT)
# per step: camera position (x, y), yaw, what it looks at and how far (the object at the frame's centre)
WALK = [((-3.0, 0.0), 0.0, "mug_t", 6.0),  # the target, beyond PIN's 5 m depth: a match here cannot be placed
        ((-3.0, 0.0), math.pi / 2, "mug_l", 3.0),  # the look-alike
        ((-3.0, 0.0), math.pi, "ball_o", 3.0),  # another object
        ((-3.0, 0.0), 0.0, "mug_t", 6.0),
        ((0.0, 0.0), 0.0, "mug_t", 3.0),  # the target 3 m ahead
        ((1.0, 0.0), 0.0, "mug_t", 2.0)]
GEODESIC = 6.0
BACK = AGENT_RADIUS + STAND_MARGIN  # without a floor map the agent stops this far short of the point below the goal


@pytest.fixture(scope="module")
def walk_set(tmp_path_factory) -> FrameSet:
    """One val episode: a camera 0.5 m high turning on the spot, then walking at the target; every object 0.5 m
    high, seen at the frame's centre against a wall as far as it. No floor map: the agent stands ``BACK`` short."""
    w = FrameSetWriter(tmp_path_factory.mktemp("nav") / "walk", camera=CameraModel(90.0))
    for oid, category, colour in (("mug_t", "mug", (200, 30, 30)), ("mug_l", "mug", (30, 30, 200)),
                                  ("ball_o", "ball", (30, 200, 30))):
        w.add_object(oid, category, "val", [make_view(colour)] * 3, [f"{oid} {k}" for k in range(3)])
    w.add_episode("e", "val", "house", "mug_t", ["mug_l", "ball_o"],
                  EpisodeGeometry(Pose(-3.0, 0.0, 0.0, 0.5), GEODESIC,  # the start heading: turned from at once
                                  {"mug_t": TARGET, "mug_l": LOOKALIKE, "ball_o": OTHER}, {"mug_t": GEODESIC}))
    roles = w.roles("e")
    for step, ((x, y), yaw, oid, distance) in enumerate(WALK):
        mask = np.zeros((SIZE, SIZE), np.uint16)
        mask[18:23, 18:23] = 1
        depth = np.full((SIZE, SIZE), distance, np.float32)  # a wall at the object's distance behind it
        w.write_frame("e", step, Frame(np.full((SIZE, SIZE, 3), 90, np.uint8), mask, {1: (oid, roles[oid])}, depth,
                                       Pose(x, y, HEIGHT, yaw)))
    return w.close()


def table_of(fs: FrameSet, scores: list[float], points=None) -> ScoreTable:
    """A score table of ``walk_set``: one score a step, its points (default: the frame's centre) carrying it."""
    points = points or [(CENTRE,)] * len(WALK)
    rows = [dict(frame_id=f"e_{step:04d}", episode_id="e", step=step, split="val", score=s, crop_scores=[s],
                 points_x=[p[0] for p in pts], points_y=[p[1] for p in pts], point_scores=[s] * len(pts), view=-1)
            for step, (s, pts) in enumerate(zip(scores, points))]
    return ScoreTable(pd.DataFrame(rows), dict(matcher="hand", matcher_id="hand@0",
                                               frameset_fingerprint=fs.fingerprint))


def stop_of(fs: FrameSet, scores: list[float], sigma: float = 0.5, geometry: dict | None = None,
            **kw) -> pd.Series:
    """The episode's row; ``geometry`` replaces fields of its ``EpisodeGeometry`` (a floor map, a position)."""
    table = table_of(fs, scores, **kw)
    places = EvalContext(fs).placements(table, "val")
    if geometry:
        places.geometry = replace(places.geometry, episodes={"e": replace(places.geometry.episodes["e"], **geometry)})
    return episodes_at(places, sigma).iloc[0]


def test_a_match_on_the_target_3_m_ahead_is_a_success(walk_set):
    # steps 0 and 3 also match the target, but 6 m away: no depth in PIN's range, so the agent walks on
    stop = stop_of(walk_set, [0.9, 0.0, 0.0, 0.9, 0.9, 0.9])
    assert stop.outcome == "success" and stop.stop_step == 4 and stop.unplaced_candidates == 2
    assert stop.landed_on == "target"
    np.testing.assert_allclose([stop.point_x, stop.point_y, stop.point_z], TARGET, atol=1e-9)
    assert (stop.stand_x, stop.stand_y) == pytest.approx((3.0 - BACK, 0.0))  # on the floor, short of the point
    assert stop.d2g == pytest.approx(math.hypot(BACK, HEIGHT))
    assert stop.steps == 4 + 0 + math.ceil((3 - BACK) / 0.25) + 1  # the 4 actions walked, no turn, the walk, stop
    assert stop.path == pytest.approx(3.0 + 3.0 - BACK) and stop.spl == pytest.approx(1.0)  # under the geodesic


def test_spl_is_below_1_for_a_success_whose_path_exceeds_the_geodesic(walk_set):
    stop = stop_of(walk_set, [0.0, 0.0, 0.0, 0.0, 0.9, 0.0], geometry=dict(geodesic_distance=4.0))
    assert stop.outcome == "success" and stop.path == pytest.approx(6.0 - BACK)
    assert stop.spl == pytest.approx(4.0 / (6.0 - BACK))


def test_a_match_on_the_lookalike_is_a_category_error(walk_set):
    stop = stop_of(walk_set, [0.0, 0.9, 0.0, 0.0, 0.2, 0.2])
    assert stop.outcome == "category error" and stop.stop_step == 1 and stop.landed_on == "same_category"
    assert (stop.stand_x, stop.stand_y) == pytest.approx((-3.0, 3.0 - BACK))
    assert stop.d2g == pytest.approx(math.dist((-3.0, 3.0 - BACK, 0.0), TARGET))
    assert stop.steps == 1 + 0 + math.ceil((3 - BACK) / 0.25) + 1 and stop.spl == 0.0


def test_a_match_elsewhere_is_neither_success_nor_category_error(walk_set):
    stop = stop_of(walk_set, [0.0, 0.0, 0.9, 0.0, 0.0, 0.0])
    assert stop.outcome == "other stop" and stop.landed_on == "other"
    assert stop.d2g == pytest.approx(math.dist((-6.0 + BACK, 0.0, 0.0), TARGET))


def test_no_match_is_not_found_with_d2g_from_where_the_agent_stands(walk_set):
    stop = stop_of(walk_set, [0.1] * len(WALK))
    assert stop.outcome == "not found" and stop.stop_step is None and stop.unplaced_candidates == 0
    # measured as a stop's: the agent's position on the floor (1, 0, 0), not its camera, to the target
    assert (stop.stand_x, stop.stand_y) == (1.0, 0.0) and stop.d2g == pytest.approx(math.hypot(2.0, HEIGHT))
    assert stop.steps == 5 and stop.path == pytest.approx(4.0) and stop.spl == 0.0


def test_turns_and_steps_to_a_point_off_the_axis(walk_set):
    # the left edge of step 4's frame at 3 m: 3 m ahead and 3 m to the left, 45 degrees off the heading
    points = [(CENTRE,)] * 4 + [((0.0, 20.0),)] + [(CENTRE,)]
    stop = stop_of(walk_set, [0.0, 0.0, 0.0, 0.0, 0.9, 0.0], points=points)
    np.testing.assert_allclose([stop.point_x, stop.point_y, stop.point_z], (3.0, 3.0, HEIGHT), atol=1e-9)
    assert stop.outcome == "other stop" and stop.landed_on == "background"
    assert stop.steps == 4 + 1 + math.ceil((math.hypot(3, 3) - BACK) / 0.25) + 1  # one turn leaves 15 degrees


def test_a_goal_on_a_high_shelf_is_out_of_reach_from_the_floor(walk_set):
    """The target on a shelf 1.4 m high, matched where it is: the point itself is on it (the rule of measuring from
    the matched point called it a success), but an agent on the floor stands 1.4 m below it at least."""
    high = (3.0, 0.0, 1.4)
    points = [(CENTRE,)] * 4 + [((20.0, 20.0 - 20.0 * (1.4 - HEIGHT) / 3.0),)] + [(CENTRE,)]  # the pixel 0.9 m up
    without_map = stop_of(walk_set, [0.0, 0.0, 0.0, 0.0, 0.9, 0.0], points=points,
                          geometry=dict(positions={"mug_t": high, "mug_l": LOOKALIKE, "ball_o": OTHER}))
    np.testing.assert_allclose([without_map.point_x, without_map.point_y, without_map.point_z], high, atol=1e-9)
    assert without_map.outcome == "other stop" and without_map.d2g == pytest.approx(math.hypot(BACK, 1.4))
    shelf = FloorMap(np.ones((100, 40), bool), 0.1, (-5.0, -1.98))  # x from -5 to 5, y from -1.98 to 2.02
    shelf.free[76:84, 16:24] = False  # the shelf and the agent's radius around it: x 2.6-3.4, y -0.38-0.42
    with_map = stop_of(walk_set, [0.0, 0.0, 0.0, 0.0, 0.9, 0.0], points=points,
                       geometry=dict(floor_map=shelf, positions={"mug_t": high, "mug_l": LOOKALIKE, "ball_o": OTHER}))
    assert (with_map.stand_x, with_map.stand_y) == pytest.approx((2.95, -0.43))  # the free cell nearest the point
    assert with_map.outcome == "other stop" and with_map.d2g == pytest.approx(math.dist((2.95, -0.43, 0.0), high))
    low = stop_of(walk_set, [0.0, 0.0, 0.0, 0.0, 0.9, 0.0], geometry=dict(floor_map=shelf))  # the target at 0.5 m
    assert low.outcome == "success" and low.d2g == pytest.approx(math.dist((2.95, -0.43, 0.0), TARGET))
    # on the map's cells: from (0, 0) to its nearest cell's centre (-0.05, -0.03), then 30 cells along x and 4 along y
    # to the cell (2.95, -0.43): 26 straight and 4 diagonal, below the shelf
    walked = math.hypot(0.05, 0.03) + 26 * 0.1 + 4 * 0.1 * math.sqrt(2)
    assert low.path == pytest.approx(3.0 + walked)
    assert low.steps == 4 + 0 + math.ceil(walked / 0.25) + 1 == 4 + 13 + 1


def test_after_a_commit_the_agent_walks_around_a_wall_not_through_it(walk_set):
    """A wall between the agent (at x = 0 when it matches) and the target (x = 3), open above y = 1: the walk to the
    standing point goes through the opening, and its length is the path's and the Steps'."""
    house = FloorMap(np.ones((100, 40), bool), 0.1, (-5.0, -1.98))
    house.free[65:67, :30] = False  # x 1.5-1.7, y -1.98 to 1.02: a wall with its opening at the top
    stop = stop_of(walk_set, [0.0, 0.0, 0.0, 0.0, 0.9, 0.0], geometry=dict(floor_map=house))
    assert stop.outcome == "success" and (stop.stand_x, stop.stand_y) == pytest.approx((2.95, -0.03))
    around = math.dist((0.0, 0.0), (1.6, 1.07)) + math.dist((1.6, 1.07), (2.95, -0.03))  # by the wall's end
    walked = stop.path - 3.0
    assert walked >= around - 0.05 and walked > math.hypot(2.95, 0.03) + 0.6  # not the straight line through it
    assert walked == pytest.approx(house.walk_length((0.0, 0.0), (2.95, -0.03)))
    assert stop.steps == 4 + 0 + math.ceil(walked / 0.25) + 1
    # from other sources on the same map (its graph built once, its lengths kept per source): by hand, 24 cells
    # straight along y from the cell (2.95, -1.93) to the cell (2.95, 0.47), both beyond the wall
    assert house.walk_length((2.95, -1.93), (2.95, 0.47)) == pytest.approx(2.4)
    assert house.walk_length((-2.05, -0.03), (2.95, -0.03)) > 5.0 + 0.6  # around the wall's end too


def test_the_floor_map_s_path_goes_around_a_wall_and_is_as_long_as_its_walk():
    free = np.ones((10, 10), bool)
    free[5, :8] = False  # a wall at x 5-6 from y 0 to 8: the walk goes round its end (y 8-10)
    floor = FloorMap(free, 1.0)
    a, b = (2.5, 0.5), (8.5, 0.5)
    path = floor.path(a, b)
    assert tuple(path[0]) == a and tuple(path[-1]) == b
    assert (path[:, 1] >= 8.0).any()  # round the wall, never through it
    assert np.hypot(*np.diff(path, axis=0).T).sum() == pytest.approx(floor.walk_length(a, b))
    apart = np.zeros((10, 10), bool)
    apart[:3], apart[6:] = True, True  # two parts of the floor: the straight line, as walk_length measures
    assert FloorMap(apart, 1.0).path(a, b).tolist() == [list(a), list(b)]


def test_spl_s_geodesic_and_the_agent_s_walk_are_measured_on_one_floor_map():
    """Round a wall by hand: from cell (2, 0) to cell (8, 0) past the wall's end at (5, 8), each half 3 diagonal and
    5 straight cells of 1 m: 10 + 6 sqrt(2). The agent that commits at the start walks exactly that far to where it
    stands beside the target, so its SPL is 1."""
    free = np.ones((10, 10), bool)
    free[5, :8] = False
    floor = FloorMap(free, 1.0)
    start, target = (2.5, 0.5), (8.6, 0.4, 0.8)  # the target on a table above cell (8, 0)
    assert floor.geodesic(start, target[:2]) == pytest.approx(10 + 6 * math.sqrt(2))
    geometry = EpisodeGeometry(Pose(*start, 0.0, 0.0), floor.geodesic(start, target[:2]), {"t": target}, {}, floor)
    stand = standing_point(geometry, np.asarray(target), np.asarray(start))
    assert tuple(stand[:2]) == (8.5, 0.5)
    assert floor.walk_length(start, stand[:2]) == pytest.approx(geometry.geodesic_distance)


def test_the_floor_map_stands_on_the_part_of_the_floor_the_agent_can_walk_to():
    free = np.zeros((10, 10), bool)
    free[:4, :] = True  # the part the agent is on: x 0-4
    free[6:, :] = True  # beyond a wall: x 6-10, nearer the goal
    floor = FloorMap(free, 1.0)
    assert tuple(floor.stand(np.array([7.0, 5.0]), np.array([1.0, 5.0]))) == (3.5, 4.5)  # nearer the agent of equals
    assert tuple(floor.stand(np.array([7.0, 5.0]), np.array([9.0, 5.0]))) == (7.5, 4.5)
    assert floor.nearest((7.0, 5.5, 0.5), 0.0) == pytest.approx(0.5 * math.sqrt(2))
    with pytest.raises(GeometryError, match="no standable cell"):
        FloorMap(np.zeros((3, 3), bool), 1.0)


def test_a_floor_map_is_stored_beside_the_episode_and_read_back(tmp_path):
    floor = FloorMap(np.eye(6, 8, dtype=bool), 0.05, (1.0, -2.0))
    w = FrameSetWriter(tmp_path / "mapped", camera=CameraModel(90.0))
    w.add_object("o", "mug", "val", [make_view((1, 2, 3))] * 3, ["a", "b", "c"])
    w.add_episode("e", "val", "s", "o", [], EpisodeGeometry(Pose(0.0, 0.0, 0.0, 0.0), 2.0, {"o": (1.0, 1.0, 0.5)},
                                                            {}, floor))
    w.write_frame("e", 0, Frame(np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.uint16), {}, None,
                                Pose(0.0, 0.0, 1.0, 0.0)))
    fs = w.close()
    read = fs.geometry.episodes["e"].floor_map
    assert (read.free == floor.free).all() and (read.cell, read.origin) == (0.05, (1.0, -2.0))
    assert fs.episode_records[0]["floor_map"]["file"] == "maps/e.png"
    before = fs.fingerprint
    assert FrameSet.load(fs.root).fingerprint == before
    other = FloorMap(floor.free.copy(), floor.cell, floor.origin)
    other.free[0, 1] = True  # one more standable cell: the same tables and frames, another floor
    atomic.write_image(fs.root / "maps" / "e.png", other.image())
    changed = FrameSet.load(fs.root)
    assert (changed.geometry.episodes["e"].floor_map.free == other.free).all()
    assert changed.fingerprint != before  # the map is part of what the fingerprint hashes
    (fs.root / "maps" / "e.png").write_bytes(b"")
    with pytest.raises(GeometryError, match=r"episode 'e': floor_map .* missing or empty file .*e\.png"):
        FrameSet.load(fs.root)


def test_metrics_are_shares_of_episodes_and_means(walk_set):
    ctx = EvalContext(walk_set)
    rows = [episodes_at(ctx.placements(table_of(walk_set, s), "val"), 0.5)
            for s in ([0.0, 0.0, 0.0, 0.0, 0.9, 0.9], [0.0, 0.9, 0.0, 0.0, 0.0, 0.0], [0.0] * 6)]
    walks = pd.concat(rows, ignore_index=True).assign(episode_id=["a", "b", "c"])
    m = metrics_of(walks)
    assert m["sr"] == pytest.approx(100 / 3) and m["ce"] == pytest.approx(100 / 3)
    assert m["not_found_pct"] == pytest.approx(100 / 3) and m["spl"] == pytest.approx(100 / 3)
    assert m["d2g"] == pytest.approx((math.hypot(BACK, HEIGHT) + math.dist((-3.0, 3.0 - BACK, 0.0), TARGET)
                                      + math.hypot(2.0, HEIGHT)) / 3)
    walked = math.ceil((3 - BACK) / 0.25)
    assert m["steps"] == pytest.approx((4 + walked + 1 + 1 + walked + 1 + 5) / 3)
    ci = navigation_metrics(walks)["ci95"]
    assert ci["sr"][0] <= m["sr"] <= ci["sr"][1] and ci["sr"] != [m["sr"], m["sr"]]


def test_a_share_every_episode_agrees_on_keeps_an_interval(walk_set):
    """0 of 3 successes: every resample repeats 0 %, and the interval is Wilson's over the resampled units
    (z^2 / (n + z^2): 56.2 % for 3 episodes, 65.8 % for 2 target instances), not "0-0"."""
    ctx = EvalContext(walk_set)
    miss = episodes_at(ctx.placements(table_of(walk_set, [0.0] * 6), "val"), 0.5)
    walks = pd.concat([miss] * 3, ignore_index=True).assign(episode_id=["a", "b", "c"])
    m = navigation_metrics(walks)
    assert m["metrics"]["sr"] == 0.0 and m["metrics"]["not_found_pct"] == 100.0
    z2 = 1.959963984540054 ** 2
    assert m["ci95"]["sr"] == pytest.approx([0.0, 100 * z2 / (3 + z2)])
    assert m["ci95"]["not_found_pct"] == pytest.approx([100 * 3 / (3 + z2), 100.0])
    assert m["ci95"]["d2g"][0] == m["ci95"]["d2g"][1]  # a measure that is no share keeps its percentile interval
    pooled = navigation_metrics(walks, clusters={"a": "o1", "b": "o1", "c": "o2"})
    assert pooled["ci95"]["sr"] == pytest.approx([0.0, 100 * z2 / (2 + z2)])


def test_evaluate_report_and_tables_carry_the_estimate(walk_set, tmp_path):
    table = table_of(walk_set, [0.9, 0.0, 0.0, 0.9, 0.9, 0.9])
    result = report(table, walk_set, tmp_path / "report", sigma=SigmaChoice(0.5, "given", "test"))
    assert result["metrics"]["sr"] == 100.0 and result["metrics"]["steps"] == 4 + math.ceil((3 - BACK) / 0.25) + 1
    assert result["navigation"]["outcomes"] == {"success": 1, "category error": 0, "other stop": 0, "not found": 0}
    assert {"navigation", "navigation_curves"} <= set(result["files"])
    saved = pd.read_csv(result["files"]["navigation"])
    assert list(saved.outcome) == ["success"] and saved.point_frame_id.iloc[0] == "e_0004"
    assert list(side_by_side([report_row(result)]).columns[2:8]) == ["SR", "SPL", "CE", "D2G", "Steps", "Not found"]
    page = (tmp_path / "report" / "report.html").read_text()
    assert "What the agent would do" in page and "episode e: success" in page


def test_the_report_page_says_where_the_agent_stands(walk_set, tmp_path):
    """Issue 66.4: the page describes the standing rule (``navigation.standing_point``), not a walk to the goal."""
    import re

    from markupsafe import escape

    report(table_of(walk_set, [0.9, 0.0, 0.0, 0.9, 0.9, 0.9]), walk_set, tmp_path / "report",
           sigma=SigmaChoice(0.5, "given", "test"))
    page = " ".join(re.sub(r"<[^>]+>", " ", (tmp_path / "report" / "report.html").read_text()).split())
    assert escape("stands on the floor nearest it: the floor map's standable cell nearest the goal or, without a "
                  "map, the floor below the goal, short of it by the agent's radius and a margin") in page
    assert "median point and stops" not in page


def test_sigma_tuned_for_sr_sees_what_first_match_cannot(walk_set):
    # the target 6 m away scores highest: the first-match objective takes 0.95 (the first match shows the target),
    # but the agent cannot place a match without depth and never stops there; SR takes 0.9 (the target at 3 m)
    table = table_of(walk_set, [0.95, 0.85, 0.0, 0.0, 0.9, 0.9])
    by_sr, by_first = tune(table, walk_set, objective="sr", split="val"), tune(table, walk_set, split="val")
    assert by_sr["sigma"] == 0.9 and by_sr["metrics_at_sigma"]["sr"] == 100.0
    assert by_first["sigma"] == 0.95 and by_first["metrics_at_sigma"]["first_match_success"] == 100.0
    assert by_first["metrics_at_sigma"]["sr"] == 0.0 and by_first["metrics_at_sigma"]["not_found_pct"] == 100.0


def test_a_frameset_without_geometry_says_why(tiny_frameset):
    rows = [dict(frame_id=f, episode_id=e, step=s, split=sp, score=0.5, crop_scores=[0.5], points_x=[1.0],
                 points_y=[1.0], point_scores=[0.5], view=-1)
            for f, e, s, sp in tiny_frameset.frames[["frame_id", "episode_id", "step", "split"]].itertuples(False)]
    table = ScoreTable(pd.DataFrame(rows), dict(matcher="hand", matcher_id="hand@0",
                                                frameset_fingerprint=tiny_frameset.fingerprint))
    result = evaluate(table, tiny_frameset, SigmaChoice(0.5, "given", "test")).result
    assert "records no geometry" in result["navigation"]["missing"] and "sr" not in result["metrics"]
    assert "SR" not in side_by_side([report_row(result)]).columns
    with pytest.raises(NavigationError, match="records no geometry"):
        EvalContext(tiny_frameset).placements(table, "val")
    with pytest.raises(TuningError, match="needs the navigation estimate"):
        tune(table, tiny_frameset, objective="sr", split="val")


def test_bad_geometry_is_a_named_error(walk_set, tmp_path):
    with pytest.raises(GeometryError, match="not finite"):
        Pose(0.0, float("nan"), 1.0, 0.0)
    with pytest.raises(GeometryError, match="negative"):
        w = FrameSetWriter(tmp_path / "neg")
        w.add_object("o", "mug", "val", [make_view((1, 2, 3))] * 3, ["a", "b", "c"])
        w.add_episode("e", "val", "s", "o", [])
        w.add_frame("e", 0, np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.uint16), {},
                    np.full((4, 4), -1.0, np.float32))
    copy = tmp_path / "nan"
    import shutil

    shutil.copytree(walk_set.root, copy)
    frames = pd.read_parquet(copy / "frames.parquet")
    frames.loc[2, "pose_yaw"] = np.nan
    frames.to_parquet(copy / "frames.parquet")
    with pytest.raises(GeometryError, match=r"frame 'e_0002' has a non-finite camera pose"):
        FrameSet.load(copy)


def test_a_writer_with_a_camera_needs_every_episodes_geometry(tmp_path):
    w = FrameSetWriter(tmp_path / "half", camera=CameraModel(42.0))
    w.add_object("o", "mug", "val", [make_view((1, 2, 3))] * 3, ["a", "b", "c"])
    w.add_episode("e", "val", "s", "o", [])
    w.write_frame("e", 0, Frame(np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.uint16), {}, None,
                                Pose(0.0, 0.0, 1.0, 0.0)))
    with pytest.raises(GeometryError, match="episode 'e' has no geometry"):
        w.close()


def test_a_rendered_pixel_lands_inside_its_object(tmp_path):
    """The renderer's own depth and pose: every pixel of a box, back-projected, lies inside the box."""
    from pin_match.data.agent import CAMERA_HEIGHT
    from pin_match.data.synth.render import Camera, Light, Renderer, vertical_fov
    from pin_match.data.synth.shapes import box

    hfov, yaw, pitch = 42.0, 0.3, -0.2  # the box ahead, left of the axis and below it
    ahead = (math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch))
    camera = Camera((0.0, 0.0, CAMERA_HEIGHT), (ahead[0], ahead[1], CAMERA_HEIGHT + ahead[2]))

    renderer = Renderer()
    try:
        centre, size = np.array([2.0, 0.7, 0.8]), np.array([0.3, 0.4, 0.5])
        body = renderer.add(box(*size), np.full((8, 8, 3), 200, np.uint8), tuple(centre))
        width, height = 180, 320
        _, ids, depth = renderer.render(camera, width, height, vertical_fov(hfov, width, height), Light())
    finally:
        renderer.close()
    ys, xs = np.nonzero(ids == body)
    assert len(xs) > 500
    points = back_project(Pose(0.0, 0.0, CAMERA_HEIGHT, yaw, pitch), CameraModel(hfov).focal_px(width),
                          (width / 2, height / 2),
                          np.stack([xs + 0.5, ys + 0.5], 1), depth[ys, xs])
    outside = np.abs(points - centre) - size / 2
    assert outside.max() < 0.01, f"a back-projected pixel lies {outside.max():.3f} m outside the box"


def test_the_synthetic_generator_records_geometry(tmp_path):
    from pin_match.data.synth import SynthSize, generate
    from pin_match.data.synth.placing import LOOKALIKE_GAP

    fs = generate(tmp_path / "s", SynthSize(seed=2, episodes=2, objects_per_family=3, frames_per_episode=8), workers=1)
    g = fs.geometry
    assert g is not None and fs.navigation_missing is None and g.camera.hfov_deg == 42.0
    for record in fs.episode_records:
        e = g.episodes[record["episode_id"]]
        target = record["goals"][0]["object_id"]
        assert e.geodesic_distance == e.geodesic_to[target] > 0
        # SPL's geodesic on the floor map the agent walks, to where it would stand beside the target
        assert e.geodesic_distance == e.floor_map.geodesic((e.start.x, e.start.y), e.positions[target][:2])
        first = g.pose(f"{record['episode_id']}_0000")
        assert (e.start.x, e.start.y, e.start.yaw) == (first.x, first.y, first.yaw)
        # issue 59: no start within reach of the target, and the target where an agent on the floor can reach it
        assert math.dist((e.start.x, e.start.y, 0.0), e.positions[target]) > 1.0 + 0.5
        assert e.floor_map is not None and e.floor_map.nearest(e.positions[target], e.start.z) <= 0.9 + 0.05
        for d in record["distractors"]:
            if d["object_category"] == record["goals"][0]["object_category"]:
                gap = np.hypot(*(np.subtract(e.positions[d["object_id"]], e.positions[target])[:2]))
                assert gap >= LOOKALIKE_GAP and d["object_id"] in e.geodesic_to
    # the target's pixels, back-projected, lie near its centre
    vis = fs.visibility[(fs.visibility.role == "target") & (fs.visibility.pixels > 200)]
    for row in vis.head(5).itertuples():
        mask, depth = fs.instance_mask(row.frame_id) == row.mask_value, fs.depth(row.frame_id)
        ys, xs = np.nonzero(mask & (depth > 0))
        points = g.back_project(row.frame_id, np.stack([xs + 0.5, ys + 0.5], 1), depth[ys, xs])
        episode = row.frame_id.rsplit("_", 1)[0]
        centre = np.asarray(g.episodes[episode].positions[row.object_id])
        assert np.median(np.linalg.norm(points - centre, axis=1)) < 0.3


# ---------------------------------------------------------------------- a PIN recording carries the same geometry
WORLD_OFFSET = np.array([10.0, 0.2, -4.0])  # Habitat's world: y up; where the house frame's origin lies in it


def to_habitat(xyz) -> list[float]:
    """A house-frame point (x, y on the floor, z up) in a Habitat world (x right, y up, z back) rotated and moved."""
    x, y, z = xyz
    return list(np.array([-y, z, -x]) + WORLD_OFFSET)


def pin_episode(fs: FrameSet, record: dict) -> dict:
    """The episode as PIN's Habitat episode holds it: world positions, start rotation [x, y, z, w], geodesic."""
    g = fs.geometry.episodes[record["episode_id"]]
    yaw = g.start.yaw  # the agent looks along -z rotated about y by yaw: house heading yaw
    goal = dict(record["goals"][0], position=to_habitat(g.positions[record["goals"][0]["object_id"]]))
    distractors = [dict(d, position=to_habitat(g.positions[d["object_id"]])) for d in record["distractors"]]
    return dict(episode_id=record["episode_id"], scene_id=record["scene_id"], split=record["split"], goals=[goal],
                distractors=distractors, start_position=to_habitat((g.start.x, g.start.y, 0.0)),
                start_rotation=[0.0, math.sin(yaw / 2), 0.0, math.cos(yaw / 2)],
                info={"geodesic_distance": g.geodesic_distance})


def agent_sensors(fs: FrameSet, frame_id: str, start: Pose) -> tuple[dict, float]:
    """PIN's gps ([forward, right] from the start, in the start's heading) and compass, and the camera pitch."""
    pose = fs.geometry.pose(frame_id)
    dx, dy = pose.x - start.x, pose.y - start.y
    c, s = math.cos(start.yaw), math.sin(start.yaw)
    forward, left = c * dx + s * dy, -s * dx + c * dy
    return dict(gps=np.array([forward, -left], np.float32), compass=np.array([pose.yaw - start.yaw])), pose.pitch


def test_a_pin_recording_yields_the_same_navigation_columns(walk_set, tmp_path):
    from pin_match.data.importer import import_recording
    from pin_match.pin_agent import FrameRecorder

    recorder = FrameRecorder(tmp_path / "rec", hfov_deg=90.0, camera_height=HEIGHT)
    for record in walk_set.episode_records:
        start = walk_set.geometry.episodes[record["episode_id"]].start
        with recorder.episode(pin_episode(walk_set, record)):
            for fid in walk_set.frames.sort_values("step").frame_id:
                sensors, pitch = agent_sensors(walk_set, fid, start)
                mask = walk_set.instance_mask(fid)
                semantic = np.where(mask == 1, {"target": 100000, "same_category": 100001, "other": 100002}[
                    walk_set.visibility[walk_set.visibility.frame_id == fid].role.iloc[0]], 0).astype(np.int32)
                recorder.record(dict(rgb=walk_set.image(fid), semantic=semantic, depth=walk_set.depth(fid), **sensors),
                                camera_pitch=pitch)
    imported = import_recording(tmp_path / "rec", walk_set.root, tmp_path / "imported")
    assert imported.geometry is not None and imported.geometry.camera.hfov_deg == 90.0
    for scores in ([0.9, 0.0, 0.0, 0.9, 0.9, 0.9], [0.0, 0.9, 0.0, 0.0, 0.2, 0.2], [0.1] * len(WALK)):
        want = stop_of(walk_set, scores)
        got = stop_of(imported, scores)
        assert got.outcome == want.outcome and got.steps == want.steps and got.landed_on == want.landed_on
        for key in ("d2g", "path", "spl"):
            assert got[key] == pytest.approx(want[key], abs=1e-5), key


def test_a_recording_with_poses_in_some_episodes_only_is_refused(walk_set, tmp_path):
    from pin_match.data.importer import import_recording
    from pin_match.pin_agent import FrameRecorder
    from pin_match.pin_agent.recorder import RecordingError

    recorder = FrameRecorder(tmp_path / "rec")
    for k, with_pose in enumerate((True, False)):
        record = dict(pin_episode(walk_set, walk_set.episode_records[0]), episode_id=f"e{k}")
        with recorder.episode(record):
            sensors = dict(gps=[0.0, 0.0], compass=[0.0]) if with_pose else {}
            recorder.record(dict(rgb=np.zeros((SIZE, SIZE, 3), np.uint8), semantic=np.zeros((SIZE, SIZE), np.int32),
                                 **sensors), camera_pitch=0.0)
    with pytest.raises(GeometryError, match="episode 'e0' recorded the agent's poses .* episode 'e1' did not"):
        import_recording(tmp_path / "rec", walk_set.root, tmp_path / "out")
    recorder = FrameRecorder(tmp_path / "rec2")
    with recorder.episode(dict(pin_episode(walk_set, walk_set.episode_records[0]), episode_id="x")):
        recorder.record(dict(rgb=np.zeros((SIZE, SIZE, 3), np.uint8), semantic=np.zeros((SIZE, SIZE), np.int32),
                             gps=[0.0, 0.0], compass=[0.0]), camera_pitch=0.0)
        with pytest.raises(RecordingError, match="no gps or compass, which earlier steps had"):
            recorder.record(dict(rgb=np.zeros((SIZE, SIZE, 3), np.uint8), semantic=np.zeros((SIZE, SIZE), np.int32)))


# ---------------------------------------------------------------------- the default synthetic set: oracles
@pytest.mark.slow
def test_oracles_on_the_default_set(default_synth):
    """Matching the target wherever it shows succeeds in every episode whose walk shows it large (1,000 px: near, so
    its point has depth) and in none whose walk never shows it: the exploration does not know the target, so the
    oracle's SR is what the walks see, not 100 % (generator 7's and 8's val split: 7 of 15; 9's tours: see
    docs/synthetic.md). Matching its
    look-alikes instead is never a success (they stand more than 2 m from it) and a category error wherever one
    shows large."""
    from pin_match.evaluation.core.oracle import oracle_table

    ctx = EvalContext(default_synth)
    sigma = 1e-9  # any pixel of the object
    val = default_synth.split("val")

    def episodes_showing(role: str, pixels: int) -> set[str]:
        """Episodes whose walk shows the role at ``pixels`` or more."""
        vis = val.visibility[(val.visibility.role == role) & (val.visibility.pixels >= pixels)]
        return set(vis.frame_id.str.rsplit("_", n=1).str[0])

    target = episodes_at(ctx.placements(oracle_table(default_synth, "target"), "val"), sigma).set_index("episode_id")
    success = set(target.index[target.outcome == "success"])
    assert set(target.outcome) <= {"success", "not found"}
    assert episodes_showing("target", 1000) <= success <= episodes_showing("target", 1) and success
    lookalike = episodes_at(ctx.placements(oracle_table(default_synth, "same_category"), "val"), sigma)
    errors = set(lookalike.episode_id[lookalike.outcome == "category error"])
    assert set(lookalike.outcome) <= {"category error", "not found"}
    assert episodes_showing("same_category", 1000) <= errors


def test_depth_at_the_sensor_s_far_limit_is_no_depth(walk_set, monkeypatch):
    """Issue 60.6: a clipping sensor reports everything beyond its range at exactly 5 m; such a point is not placed."""
    monkeypatch.setattr(FrameSet, "depth", lambda self, frame_id: np.full((SIZE, SIZE), 5.0, np.float32))
    stop = stop_of(walk_set, [0.0, 0.0, 0.0, 0.0, 0.9, 0.0])
    assert stop.outcome == "not found" and stop.unplaced_candidates == 1
    monkeypatch.setattr(FrameSet, "depth", lambda self, frame_id: np.full((SIZE, SIZE), 4.99, np.float32))
    assert stop_of(walk_set, [0.0, 0.0, 0.0, 0.0, 0.9, 0.0]).unplaced_candidates == 0
