"""The closed loop: a firing sends the agent up to its candidate with PIN's actions, what it sees there decides, a
rejected goal is remembered by the cells of its own map, and every action counts; nothing reads the ground truth."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pin_match.data.geometry import FloorMap
from pin_match.data.walkup import WalkUp, pose_key, remembered_cells, walk_up
from pin_match.evaluation.core.stop import ApproachVerify, Decision, StopPolicy

# ------------------------------------------------------------------ the walk-up's actions, counted by hand
CELL = 0.1  # a 10 x 4 m floor, x from -5, y from -2: cell centres at -4.95 + 0.1 i, -1.95 + 0.1 j
FREE = np.ones((100, 40), bool)
FREE[:, 32:] = False  # a sideboard along y >= 1.25
FREE[57:, :] = False  # a shelf along x >= 0.75
FLOOR = FloorMap(FREE, CELL, (-5.0, -2.0))
CLUTTER = np.array([-2.95, 1.55, 0.5])  # on the sideboard, 1.5 m ahead of (-2.95, 0.05) facing +y
TARGET = np.array([1.05, 0.05, 0.5])  # on the shelf, 2 m ahead of (-0.95, 0.05) facing +x


def test_a_walk_up_is_pin_s_actions_along_the_floor_to_beside_the_goal():
    """From (-2.95, 0.05) facing +y to the clutter: the nearest standable cell to it is (-2.95, 1.15), 1.1 m ahead:
    four 0.25 m steps and one of 0.1 m, no turn (it faces it), then two looks down (the goal 0.81 m below the camera,
    0.4 m away: 64 degrees down, two 30-degree tilts). The walk back: two tilts up, an about-turn (6 turns), five
    steps, six turns to the old heading."""
    walkup = walk_up(FLOOR, -2.95, 0.05, math.pi / 2, CLUTTER)
    assert walkup.actions == 7 and walkup.back == 2 + 6 + 5 + 6 and walkup.walked == pytest.approx(1.1)
    assert walkup.end == pytest.approx((-2.95, 1.15))
    assert [p[3] for p in walkup.poses] == pytest.approx([0, 0, 0, 0, 0, -math.pi / 6, -math.pi / 3])
    assert walkup.distances == pytest.approx((1.25, 1.0, 0.75, 0.5, 0.4, 0.4, 0.4))
    assert walkup.needed(1.0 + 1e-9) == [1, 2, 3, 4, 5, 6] and walkup.needed(0.2) == [4, 5, 6]  # else the nearest
    turned = walk_up(FLOOR, -2.95, 0.05, -math.pi / 2, CLUTTER)  # facing away: six turns first
    assert turned.actions == 6 + 7 and turned.poses[5][2] == pytest.approx(math.pi / 2)
    assert all(p[:2] == pytest.approx((-2.95, 0.05)) for p in turned.poses[:6])
    assert len({pose_key(p) for p in walkup.poses}) == 7  # every view has a name of its own


def test_a_rejected_goal_is_remembered_by_the_cells_around_it():
    key, around = remembered_cells(np.array([-2.95, 1.55, 0.5]))
    assert key == (-12, 6) and key in around
    assert remembered_cells(np.array([-2.95, 1.65, 0.3]))[0] in around  # 10 cm further: the same thing
    assert remembered_cells(np.array([-2.95, 2.2, 0.5]))[0] not in around  # 65 cm further: something else


# ------------------------------------------------------------------ the loop on a hand-built episode
SIZE = 40  # square frames, HFOV 90 degrees: the centre pixel looks straight ahead
WALK = [((-2.95, 0.05), math.pi / 2, None, 1.5),  # the clutter on the sideboard
        ((-2.95, 0.05), math.pi / 2, None, 1.6),  # the same clutter, 10 cm further: remembered, passed over
        ((-0.95, 0.05), 0.0, "mug_t", 2.0),  # the target on the shelf
        ((0.05, 0.05), 0.0, None, 0.6)]
SCORES = [0.9, 0.8, 0.9, 0.0]
POSITIONS = {"mug_t": tuple(TARGET), "mug_l": (-4.5, -1.5, 0.5), "ball_o": (-4.5, 1.0, 0.5)}


@pytest.fixture(scope="module")
def loop_set(tmp_path_factory):
    from conftest import make_view
    from pin_match.data.geometry import CameraModel, EpisodeGeometry, Pose
    from pin_match.data.writer import Frame, FrameSetWriter

    w = FrameSetWriter(tmp_path_factory.mktemp("loop") / "set", camera=CameraModel(90.0))
    for oid, category, colour in (("mug_t", "mug", (200, 30, 30)), ("mug_l", "mug", (30, 30, 200)),
                                  ("ball_o", "ball", (30, 200, 30))):
        w.add_object(oid, category, "val", [make_view(colour)] * 3, [f"{oid} {k}" for k in range(3)])
    w.add_episode("e", "val", "house", "mug_t", ["mug_l", "ball_o"],
                  EpisodeGeometry(Pose(-2.95, 0.05, 0.0, math.pi / 2), 4.0, POSITIONS, {"mug_t": 4.0}, FLOOR))
    roles = w.roles("e")
    for step, ((x, y), yaw, oid, distance) in enumerate(WALK):
        mask = np.zeros((SIZE, SIZE), np.uint16)
        legend = {}
        if oid is not None:
            mask[18:23, 18:23] = 1
            legend = {1: (oid, roles[oid])}
        depth = np.full((SIZE, SIZE), distance, np.float32)
        w.write_frame("e", step, Frame(np.full((SIZE, SIZE, 3), 90, np.uint8), mask, legend, depth,
                                       Pose(x, y, 0.5, yaw)))
    return w.close()


def table_of(fs, scores):
    from pin_match.scoring.table import ScoreTable

    rows = [dict(frame_id=f"e_{step:04d}", episode_id="e", step=step, split="val", score=s, crop_scores=[s],
                 points_x=[20.0], points_y=[20.0], point_scores=[s], view=-1) for step, s in enumerate(scores)]
    return ScoreTable(pd.DataFrame(rows), dict(matcher="hand", matcher_id="hand@0",
                                               frameset_fingerprint=fs.fingerprint))


class Rendered:
    """Walk-up views as a renderer and a matcher would give them: a view's score depends on where it stands (by the
    shelf: 0.9; by the sideboard: 0.2), never on what the set says is there; each asked for once, then resolved."""

    def __init__(self) -> None:
        self.scores: dict[tuple, float] = {}
        self.pending: list[tuple] = []
        self.rounds = 0

    def views(self, episode_id: str, walkup: WalkUp, within: float):
        key = (episode_id, walkup.end)
        if key not in self.scores:
            self.pending.append(key)
            return None
        return tuple((walkup.distances[k], self.scores[key]) for k in walkup.needed(within))

    def resolve(self) -> bool:
        if not self.pending:
            return False
        self.scores |= {key: 0.9 if key[1][0] > 0 else 0.2 for key in self.pending}
        self.pending, self.rounds = [], self.rounds + 1
        return True


def placements(fs, source):
    from pin_match.evaluation import EvalContext

    return EvalContext(fs, walk_ups=lambda table: source).placements(table_of(fs, SCORES), "val")


POLICY = ApproachVerify(distance=1.0, sigma2=0.6)


def test_a_firing_on_clutter_is_walked_up_to_rejected_and_the_target_then_committed_to(loop_set):
    """First match stops on the clutter. Approach-verify walks up to it (7 actions: the test above), sees 0.2 < 0.6
    within 1 m, rejects it, walks back (19 actions) and resumes; step 1 fires on the same goal cells: passed over;
    step 2 fires on the target: 2 m ahead, the shelf 0.4 m short of it: seven steps (1.6 m) and two tilts, 0.9 seen,
    committed. Steps = 2 (the walk to step 2) + 7 + 19 + 9 + 1 (stop) = 38; path = 2 + 2 x 1.1 + 1.6 m; it stands
    0.4 m short of the target and 0.5 m below it: a success, SPL 4 / 5.8. One round of rendering: waiting on the
    clutter's walk-up, the episode asks for the next candidates' too (``navigation.PREFETCH``)."""
    from pin_match.evaluation.core.navigation import episodes_at, walk_decisions

    source = Rendered()
    places = placements(loop_set, source)
    assert episodes_at(places, 0.5).iloc[0].outcome == "other stop"  # PIN's first match: on the clutter
    row = episodes_at(places, 0.5, POLICY).iloc[0]
    assert walk_decisions(places, 0.5, POLICY)[0] == [Decision(0, 2, 2, (0, 2), 0, ((0, 0),))]
    assert (row.outcome, row.stop_step, row.landed_on, row.rejections) == ("success", 2, "target", "0:background:0.200")
    assert row.steps == 2 + 7 + 19 + 9 + 1 and row.path == pytest.approx(2.0 + 2 * 1.1 + 1.6)
    assert (row.stand_x, row.stand_y) == pytest.approx((0.65, 0.05)) and row.d2g == pytest.approx(math.hypot(0.4, 0.5))
    assert row.spl == pytest.approx(4.0 / 5.8) and source.rounds == 1


def test_the_decisions_read_no_ground_truth(loop_set, tmp_path):
    """The same walk with every object moved (one onto the clutter, where a view snapped to the nearest object would
    change the close look) and every role relabelled: the same decisions, steps and path."""
    from pin_match.data.frameset import FrameSet
    from pin_match.evaluation.core.navigation import episodes_at, walk_decisions

    root = tmp_path / "relabelled"
    shutil.copytree(loop_set.root, root)
    records = json.loads((root / "episodes.json").read_text())
    episode = records["episodes"][0]
    for goal in [*episode["goals"], *episode["distractors"]]:
        goal["position"] = {"mug_t": [-2.95, 1.6, 0.5], "mug_l": [1.0, 0.1, 0.5], "ball_o": [0.0, 1.0, 0.5]}[
            goal["object_id"]]
    (root / "episodes.json").write_text(json.dumps(records))
    visibility = pd.read_parquet(root / "visibility.parquet")
    visibility["role"] = "other"
    visibility.to_parquet(root / "visibility.parquet")
    moved = FrameSet.load(root)
    columns = ["stop_step", "steps", "path", "rejected", "candidates", "stand_x", "stand_y"]
    rows = [episodes_at(placements(fs, Rendered()), 0.5, POLICY).iloc[0][columns] for fs in (loop_set, moved)]
    assert rows[0].equals(rows[1])
    assert walk_decisions(placements(moved, Rendered()), 0.5, POLICY)[0] == [Decision(0, 2, 2, (0, 2), 0, ((0, 0),))]


def test_the_loop_runs_pin_detector_as_the_agent_would(loop_set):
    """``PinDetector`` driven step by step on the same walk: the agent places each candidate's goal, walks it up with
    the same actions, feeds every view it sees (its distance from its map), arrives, walks back and resumes. The same
    decision as offline, and the actions it takes add up to the offline Steps."""
    from test_pin_agent import HAND_REFERENCES
    from toys import HandSet

    from pin_match.contract.results import MatchResult
    from pin_match.evaluation.core.navigation import episodes_at, walk_decisions
    from pin_match.pin_agent import PinDetector

    source = Rendered()
    places = placements(loop_set, source)
    offline = walk_decisions(places, 0.5, POLICY)[0][0]
    steps = episodes_at(places, 0.5, POLICY).iloc[0].steps
    goals = {t: places.place(places.frame_ids[t], 0.5)[0] for t in range(3)}  # the steps that fire
    matcher = HandSet()
    detector = PinDetector(matcher, sigma=0.5, policy=POLICY, resize_dim=None, squares_per_step=1)
    now = {"distance": 0.0}
    detector.reset(goal=lambda step: goals[step], distance=lambda: now["distance"])
    square = np.zeros((8, 8, 3), np.uint8)
    actions = 0
    for step, score in enumerate(SCORES):
        actions += step > 0  # each step of the walk after the first is one action
        matcher.result = MatchResult(score=score, points=[[4, 4]])
        detector(square, HAND_REFERENCES, category=None)
        if detector.approaching is None:
            continue
        (x, y), yaw = WALK[step][0], WALK[step][1]
        walkup = walk_up(FLOOR, x, y, yaw, goals[detector.approaching])
        for distance in walkup.distances:  # every view on its way, its score as the renderer's above
            now["distance"] = distance
            matcher.result = MatchResult(score=0.9 if walkup.end[0] > 0 else 0.2, points=[[4, 4]])
            detector(square, HAND_REFERENCES, category=None)
        actions += walkup.actions
        detector.arrived()
        if detector.committed is not None:
            break
        actions += walkup.back  # walking back: not looked at
        detector.resume()
    assert detector.decision == offline and detector.committed.step == 2
    assert actions + 1 == steps  # and the stop
    answer = detector(square, HAND_REFERENCES, category=None)  # the next call after the commit on arrival
    assert answer[4, 4] == 1.0 and answer.sum() == 1  # the candidate's point, for the agent's goal
    assert not detector(square, HAND_REFERENCES, category=None).any()  # once


def test_a_set_with_nothing_to_walk_up_to_says_so(loop_set):
    from pin_match.evaluation import EvalContext
    from pin_match.evaluation.core.navigation import NavigationError, episodes_at

    places = EvalContext(loop_set).placements(table_of(loop_set, SCORES), "val")
    with pytest.raises(NavigationError, match="has no walk-ups: a synthetic set renders them"):
        episodes_at(places, 0.5, POLICY)
    assert episodes_at(places, 0.5, StopPolicy()).iloc[0].stop_step == 0  # other policies need none
    from pin_match.scoring.walkups import walkup_scorer

    assert walkup_scorer(loop_set, []) is None  # not the generator's: no house to render a walk-up in


# ------------------------------------------------------------------ rendered in the house, scored by a matcher
@pytest.fixture(scope="module")
def tiny_synth(tmp_path_factory):
    from pin_match.data.synth import SynthSize, generate

    return generate(tmp_path_factory.mktemp("synth") / "fs", SynthSize(seed=3, episodes=2, objects_per_family=2,
                                                                       frames_per_episode=40, rooms=2), workers=1)


@pytest.mark.slow
def test_walk_ups_are_rendered_in_the_house_once_and_scored_through_the_engine(tiny_synth, tmp_path):
    """``color`` on a rendered house under approach-verify: the walk-ups of every candidate it walks up to are
    rendered (each view once, kept by pose) and scored as frame-sets of their own; a second run with a fresh source
    renders nothing and scores nothing again and gives the same rows."""
    from pin_match.contract.registry import create_matcher
    from pin_match.data.frameset import FrameSet
    from pin_match.evaluation import EvalContext
    from pin_match.evaluation.core.navigation import episodes_at
    from pin_match.scoring import score
    from pin_match.scoring.walkups import walkup_scorer

    matcher = create_matcher("color")
    table = score(tiny_synth, matcher, out=tmp_path)
    policy = ApproachVerify(distance=1.0, sigma2=0.95)  # a line few views reach: it walks up to several candidates

    def rows():
        ctx = EvalContext(tiny_synth, walk_ups=walkup_scorer(tiny_synth, [matcher], tmp_path))
        return episodes_at(ctx.placements(table, "val"), 0.5, policy)

    first = rows()
    views = sorted((tmp_path / "walkups" / tiny_synth.fingerprint / "views").rglob("*.jpg"))
    sets = sorted((tmp_path / "walkups" / tiny_synth.fingerprint / "sets").iterdir())
    assert first.candidates.sum() >= 1 and len(views) >= 1 and sets
    walked = FrameSet.load(sets[0])
    assert walked.manifest["provenance"]["kind"] == "walk-ups" and set(walked.episodes.split) == {"val"}
    assert len(walked.frames) == len(set(walked.frames.sha256)) or len(walked.episodes) > 1
    stamps = {p: p.stat().st_mtime_ns for p in views}
    again = rows()
    pd.testing.assert_frame_equal(first, again)
    assert {p: p.stat().st_mtime_ns for p in views} == stamps


@pytest.mark.slow
def test_a_set_s_houses_are_staged_again_with_its_own_rooms(tiny_synth, tmp_path):
    """A set of two-room houses is staged again in two-room houses (the walk-ups' house is the walk's), whatever the
    default."""
    from pin_match.data.synth.scene import make_house
    from pin_match.data.synth.walkups import SynthHouses

    plans = SynthHouses(tiny_synth, tmp_path / "views").plans.values()
    assert tiny_synth.manifest["provenance"]["rooms"] == 2 and {p.rooms for p in plans} == {2}
    assert all(len(make_house(np.random.default_rng(p.scene_seed), p.rooms).rooms) == 2 for p in plans)


@pytest.mark.slow
def test_a_set_this_install_would_stage_differently_is_refused(tiny_synth, tmp_path):
    from pin_match.data.frameset import FrameSet
    from pin_match.data.synth.walkups import HouseError, SynthHouses

    root = tmp_path / "other"
    shutil.copytree(tiny_synth.root, root)
    manifest = json.loads((root / "frameset.json").read_text())
    manifest["provenance"]["definition"] = "0123456789abcdef"
    (root / "frameset.json").write_text(json.dumps(manifest))
    with pytest.raises(HouseError, match=r"definition 0123456789abcdef; this install \(generator 10\) stages "
                                         r"definition [0-9a-f]{16}: its houses would differ"):
        SynthHouses(FrameSet.load(root), tmp_path / "views")


def test_a_house_s_definition_reads_every_module_that_makes_it_and_not_the_view_cache():
    """Every module of ``synth`` is in the definition but ``walkups`` (which keeps views, not houses): a new module
    must be added to it, or named here as one that makes no house."""
    from pin_match.data.synth.size import DEFINITION_READS

    package = Path(__file__).resolve().parents[1] / "pin_match"
    synth = {p.relative_to(package).as_posix() for p in (package / "data" / "synth").glob("*.py")}
    assert synth - set(DEFINITION_READS) == {"data/synth/walkups.py"}
    assert all((package / read).is_file() for read in DEFINITION_READS)
