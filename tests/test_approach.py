"""The approach-verify stop policy: walk up to a candidate, look again from close by, commit or reject and walk on."""

from __future__ import annotations

import numpy as np
import pytest

from pin_match.evaluation.core.stop import (
    ApproachVerify,
    CloseLook,
    Decision,
    PolicyError,
    StopPolicy,
    latest_counted,
    one_walk,
)

WALK = np.array([0.1, 0.7, 0.8, 0.2, 0.9, 0.3])  # firings at 0.5: steps 1, 2 (the look-alike) and 4 (the target)
LOOKS = {1: CloseLook("lookalike", ((2.0, 0.9), (0.8, 0.3))),  # seen well from 2 m, poorly from 0.8 m
         2: CloseLook("lookalike", ((0.5, 0.95),)),  # the same object: never walked up to again
         4: CloseLook("target", ((1.5, 0.2), (0.9, 0.65)))}


@pytest.mark.parametrize("text, policy", [
    ("approach:1", ApproachVerify(distance=1.0)),
    ("approach:1.5+0.6", ApproachVerify(distance=1.5, sigma2=0.6)),
    ("approach:0.5-0.25@2-of-3", ApproachVerify(2, 3, distance=0.5, sigma2=-0.25)),
    ("approach:1+0.123456789", ApproachVerify(distance=1.0, sigma2=0.123456789)),
])
def test_the_text_of_an_approach_policy_round_trips(text, policy):
    assert StopPolicy.parse(text) == policy and StopPolicy.parse(str(policy)) == policy


@pytest.mark.parametrize("text, message", [("approach:", "write an approach-verify one as approach:D"),
                                           ("approach:-1", "approach:D"), ("approach:1+", "approach:D"),
                                           ("approach:x", "approach:D"),
                                           ("approach:0", "approach:0: need a finite approach distance above 0")])
def test_a_bad_approach_policy_says_how_to_write_one(text, message):
    with pytest.raises(PolicyError, match=message):
        StopPolicy.parse(text)


def test_a_rejected_lookalike_is_remembered_and_the_target_verified():
    """Step 1's candidate is seen from within 1 m at 0.3 < 0.6: rejected (the 0.9 from 2 m is too far to count).
    Step 2 fires on the same object: passed over without walking up to it. Step 4's target is seen at 0.65 from
    0.9 m: committed there."""
    asked = []

    def verify(frame: int) -> CloseLook:
        asked.append(frame)
        return LOOKS[frame]

    decision = ApproachVerify(distance=1.0, sigma2=0.6).decide(one_walk(WALK), 0.5, verify=verify)[0]
    assert decision == Decision(1, 4, 4, (1, 4), 0, ((1, 1),))
    assert asked == [1, 2, 4]  # step 2's object is known from where its goal is: nothing seen of it


def test_without_a_view_within_d_the_nearest_view_stands_for_them():
    # from 0.5 m nothing is within D: the 0.8 m view (0.3) is the nearest, so step 1 is rejected; from 2.5 m the 2 m
    # view (0.9) counts and step 1 is committed to
    near = ApproachVerify(distance=0.5, sigma2=0.6).decide(one_walk(WALK), 0.5, verify=LOOKS.__getitem__)[0]
    assert near.rejected[0] == (1, 1)
    far = ApproachVerify(distance=2.5, sigma2=0.6).decide(one_walk(WALK), 0.5, verify=LOOKS.__getitem__)[0]
    assert (far.stop, far.chosen, far.rejected) == (1, 1, ())


def test_a_candidate_with_no_views_is_judged_on_its_own_frame():
    """Without views (a candidate on nothing the set has approach views of, or no ``verify`` at all) the
    candidate's own score meets the second line: 0.7 and 0.8 fall short of 0.85, 0.9 clears it."""
    policy = ApproachVerify(distance=1.0, sigma2=0.85)
    decision = policy.decide(one_walk(WALK), 0.5)[0]
    assert decision == Decision(1, 4, 4, (1, 2, 4), 0, ((1, 1), (2, 2)))
    assert ApproachVerify(distance=1.0).decide(one_walk(WALK), 0.5)[0] == StopPolicy().decide(one_walk(WALK), 0.5)[0]


def test_every_candidate_rejected_leaves_the_agent_still_looking():
    decision = ApproachVerify(distance=1.0, sigma2=0.99).decide(one_walk(WALK), 0.5, verify=LOOKS.__getitem__)[0]
    assert (decision.fired, decision.stop, decision.chosen) == (1, None, None)
    assert decision.rejected == ((1, 1), (4, 4))


def test_nothing_after_the_commit_nor_of_a_candidate_not_walked_up_to_is_read():
    policy = ApproachVerify(distance=1.0, sigma2=0.6)
    base = policy.decide(one_walk(WALK), 0.5, verify=LOOKS.__getitem__)[0]
    rng = np.random.default_rng(0)
    for _ in range(20):
        later = WALK.copy()
        later[5:] = rng.uniform(0, 1, len(later) - 5)  # every score after the commit at step 4

        def verify(frame: int) -> CloseLook:
            assert frame <= 4, "a candidate after the commit was looked at"
            return LOOKS[frame]

        assert policy.decide(one_walk(later), 0.5, verify=verify)[0] == base


@pytest.mark.parametrize("k, n", [(1, 1), (2, 3), (3, 5)])
def test_a_window_first_fires_on_its_candidate_s_own_frame(k, n):
    """The walk-up departs from the candidate frame's pose because the agent leaves its walk there: under any window
    the first firing whose candidate is frame c is frame c itself (``ApproachVerify``)."""
    rng = np.random.default_rng(k * 10 + n)
    policy = ApproachVerify(k, n, distance=1.0)
    for _ in range(200):
        arr = one_walk(rng.uniform(0, 1, 30))
        counted = arr.score >= 0.6
        fired = policy._window_fires(arr, counted)
        source = latest_counted(arr, counted)
        first_firing: dict[int, int] = {}
        for t in np.flatnonzero(fired):
            first_firing.setdefault(int(source[t]), int(t))
        assert all(candidate == t for candidate, t in first_firing.items())


def test_a_live_approach_arrives_only_when_asked():
    """Live, the views of the candidate it walks up to are not there yet: the decision names the candidate."""
    def pending(frame: int) -> CloseLook:
        return CloseLook(frame, None)

    decision = ApproachVerify(distance=1.0).decide(one_walk(WALK), 0.5, verify=pending)[0]
    assert decision == Decision(1, None, None, (1,), 0, (), approaching=1)


# ------------------------------------------------------------------ the detours, on hand-built geometry
SIZE, CENTRE, HEIGHT = 40, (20.0, 20.0), 0.5  # frames of 40 px, HFOV 90: the centre pixel looks straight ahead
TARGET, LOOKALIKE, OTHER = (3.0, 0.0, HEIGHT), (-3.0, 3.0, HEIGHT), (-6.0, 0.0, HEIGHT)
WALK_STEPS = [((-3.0, 0.0), np.pi / 2, "mug_l", 3.0),  # the look-alike 3 m to the left
              ((-3.0, 0.0), np.pi, "ball_o", 3.0),  # the other object
              ((0.0, 0.0), 0.0, "mug_t", 3.0),  # the target 3 m ahead
              ((1.0, 0.0), 0.0, "mug_t", 2.0)]
# approach views: (object, camera position, yaw, distance to the object)
VIEWS = [("mug_l", (-3.0, 1.5), np.pi / 2, 1.5), ("mug_l", (-3.0, 2.2), np.pi / 2, 0.8),
         ("mug_t", (1.5, 0.0), 0.0, 1.5), ("mug_t", (2.2, 0.0), 0.0, 0.8)]


@pytest.fixture(scope="module")
def approach_set(tmp_path_factory):
    """One val episode without a floor map: a walk of four steps, then two approach views of the look-alike and two
    of the target (none of the ball), each object at the centre of its frames against a wall as far as it."""
    from conftest import make_view
    from pin_match.data.geometry import CameraModel, EpisodeGeometry, Pose
    from pin_match.data.writer import Frame, FrameSetWriter

    w = FrameSetWriter(tmp_path_factory.mktemp("approach") / "set", camera=CameraModel(90.0))
    for oid, category, colour in (("mug_t", "mug", (200, 30, 30)), ("mug_l", "mug", (30, 30, 200)),
                                  ("ball_o", "ball", (30, 200, 30))):
        w.add_object(oid, category, "val", [make_view(colour)] * 3, [f"{oid} {k}" for k in range(3)])
    w.add_episode("e", "val", "house", "mug_t", ["mug_l", "ball_o"],
                  EpisodeGeometry(Pose(-3.0, 0.0, 0.0, np.pi / 2), 6.0,
                                  {"mug_t": TARGET, "mug_l": LOOKALIKE, "ball_o": OTHER}, {"mug_t": 6.0}))
    roles = w.roles("e")
    steps = [(xy, yaw, oid, d, None) for xy, yaw, oid, d in WALK_STEPS] + \
        [(xy, yaw, oid, d, (oid, d)) for oid, xy, yaw, d in VIEWS]
    for step, ((x, y), yaw, oid, distance, approach) in enumerate(steps):
        mask = np.zeros((SIZE, SIZE), np.uint16)
        mask[18:23, 18:23] = 1
        depth = np.full((SIZE, SIZE), distance, np.float32)
        w.write_frame("e", step, Frame(np.full((SIZE, SIZE, 3), 90, np.uint8), mask, {1: (oid, roles[oid])}, depth,
                                       Pose(x, y, HEIGHT, yaw), approach=approach))
    return w.close()


def test_approach_views_are_frames_of_their_own_kind_in_the_fingerprint(approach_set, tmp_path):
    import shutil

    import pandas as pd

    from pin_match.data.frameset import FrameSet

    views = approach_set.approach_views
    assert views.step.tolist() == [4, 5, 6, 7] and views.approach_of.tolist() == [v[0] for v in VIEWS]
    assert views.approach_distance.tolist() == [v[3] for v in VIEWS]
    root = tmp_path / "copy"
    shutil.copytree(approach_set.root, root)
    rows = pd.read_parquet(root / "frames.parquet")
    rows.loc[rows.step == 7, "approach_of"] = "mug_l"  # the last view now said to be of the look-alike
    rows.to_parquet(root / "frames.parquet")
    assert FrameSet.load(root).fingerprint != approach_set.fingerprint


def test_the_writer_refuses_an_approach_view_without_a_distance(tmp_path):
    from pin_match.data.frameset import FrameSetError
    from pin_match.data.writer import Frame, encode_frame

    frame = Frame(np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.uint16), {}, approach=("mug_t", -1.0))
    with pytest.raises(FrameSetError, match=r"frame e_0003: approach \('mug_t', -1.0\) is not"):
        encode_frame(tmp_path, "e", 3, frame)


def approach_table(fs, walk_scores, view_scores):
    import pandas as pd

    from pin_match.scoring.table import ScoreTable

    scores = [*walk_scores, *view_scores]
    rows = [dict(frame_id=f"e_{step:04d}", episode_id="e", step=step, split="val", score=s, crop_scores=[s],
                 points_x=[CENTRE[0]], points_y=[CENTRE[1]], point_scores=[s], view=-1)
            for step, s in enumerate(scores)]
    return ScoreTable(pd.DataFrame(rows), dict(matcher="hand", matcher_id="hand@0",
                                               frameset_fingerprint=fs.fingerprint))


def test_a_rejected_lookalike_then_the_target_counts_every_step_of_the_detour(approach_set):
    """Step 0 fires on the look-alike 3 m to the left: the agent walks up to it (3 m less its radius and margin, no
    turn: it faces it), sees it at 0.3 from 0.8 m (the 0.8 from 1.5 m is beyond D = 1 m), rejects it, turns about
    (6 turns) and walks back. Step 2 fires on the target 3 m ahead; seen at 0.85 from 0.8 m, it is committed to.
    Hand-counted: Steps = 2 (walk) + 2 x 11 + 6 (detour) + 11 + 1 (to the target, the stop); path = 3 + 2 x 2.7 +
    2.7 m. First match stops on the look-alike: a category error."""
    from pin_match.evaluation import EvalContext
    from pin_match.evaluation.core.navigation import AGENT_RADIUS, STAND_MARGIN, episodes_at, metrics_of

    back = AGENT_RADIUS + STAND_MARGIN
    leg = 3.0 - back
    table = approach_table(approach_set, [0.9, 0.0, 0.9, 0.2], [0.8, 0.3, 0.4, 0.85])
    ctx = EvalContext(approach_set)
    assert len(ctx.arrays(table, "val").score) == 4  # the approach views are not frames of the walk
    places = ctx.placements(table, "val")
    first = episodes_at(places, 0.5).iloc[0]
    assert first.outcome == "category error" and first.stop_step == 0
    row = episodes_at(places, 0.5, ApproachVerify(distance=1.0, sigma2=0.6)).iloc[0]
    assert row.outcome == "success" and row.stop_step == 2 and row.landed_on == "target"
    assert row.rejected == 1 and row.rejected_lookalike == 1 and row.rejected_target == 0
    assert row.rejections == "0:same_category:0.300"
    forward = int(np.ceil(leg / 0.25))
    assert row.steps == 2 + (2 * forward + 6) + forward + 1
    assert row.path == pytest.approx(3.0 + 2 * leg + leg)
    assert row.spl == pytest.approx(6.0 / (3.0 + 3 * leg))
    metrics = metrics_of(episodes_at(places, 0.5, ApproachVerify(distance=1.0, sigma2=0.6)))
    assert metrics["rejections"] == 1 and metrics["rejected_lookalike_pct"] == 100 and metrics["sr"] == 100
    # D = 2 m reads the look-alike's 0.8 from 1.5 m: it is committed to, a category error after the walk up
    near = episodes_at(places, 0.5, ApproachVerify(distance=2.0, sigma2=0.6)).iloc[0]
    assert near.outcome == "category error" and near.rejected == 0 and near.steps == 0 + forward + 1


def test_a_stop_that_the_detours_push_past_pins_step_limit_is_no_stop(approach_set, monkeypatch):
    """The rejected look-alike's detour and the walk to the target take 42 steps (the test above): under a limit
    of 42 the stop is a success, under 41 the episode ends before the agent stops: not found, at the limit."""
    from pin_match.evaluation import EvalContext
    from pin_match.evaluation.core import navigation

    places = EvalContext(approach_set).placements(approach_table(approach_set, [0.9, 0.0, 0.9, 0.2],
                                                                 [0.8, 0.3, 0.4, 0.85]), "val")
    policy = ApproachVerify(distance=1.0, sigma2=0.6)
    monkeypatch.setattr(navigation, "MAX_STEPS", 42)
    assert navigation.episodes_at(places, 0.5, policy).iloc[0].outcome == "success"
    monkeypatch.setattr(navigation, "MAX_STEPS", 41)
    row = navigation.episodes_at(places, 0.5, policy).iloc[0]
    assert (row.outcome, row.steps, row.spl, row.rejected) == ("not found", 41, 0.0, 1)
    assert row.stop_step is None or np.isnan(row.stop_step)


def test_a_candidate_with_no_approach_views_is_judged_on_its_own_frame(approach_set):
    """The ball has no approach views: a firing on it (0.7) is rejected at a second line of 0.75 after its detour
    (3 m ahead: no turn), and the walk's end comes with nothing else: not found, the detour's steps
    counted."""
    from pin_match.evaluation import EvalContext
    from pin_match.evaluation.core.navigation import AGENT_RADIUS, STAND_MARGIN, episodes_at

    forward = int(np.ceil((3.0 - AGENT_RADIUS - STAND_MARGIN) / 0.25))
    table = approach_table(approach_set, [0.0, 0.7, 0.0, 0.0], [0.9, 0.9, 0.9, 0.9])
    places = EvalContext(approach_set).placements(table, "val")
    row = episodes_at(places, 0.5, ApproachVerify(distance=1.0, sigma2=0.75)).iloc[0]
    assert row.outcome == "not found" and row.rejected == 1 and row.rejections == "1:other:0.700"
    assert row.steps == 3 + 0 + 2 * forward + 6


def test_a_pin_recording_keeps_its_approach_views_and_the_decision(approach_set, tmp_path):
    """The walk and its approach views recorded as PIN's agent would (``FrameRecorder.record(..., approach=)``) and
    imported: the same approach views, and the approach-verify policy rejects and commits as on the set itself."""
    from test_navigation import agent_sensors, pin_episode

    from pin_match.data.importer import import_recording
    from pin_match.evaluation import EvalContext
    from pin_match.evaluation.core.navigation import episodes_at
    from pin_match.pin_agent import FrameRecorder
    from pin_match.pin_agent.recorder import RecordingError

    codes = {"target": 100000, "same_category": 100001, "other": 100002}
    views = approach_set.approach_views.set_index("frame_id")
    record = approach_set.episode_records[0]
    start = approach_set.geometry.episodes[record["episode_id"]].start
    recorder = FrameRecorder(tmp_path / "rec", hfov_deg=90.0, camera_height=HEIGHT)
    with recorder.episode(pin_episode(approach_set, record)):
        for fid in approach_set.frames.sort_values("step").frame_id:
            sensors, pitch = agent_sensors(approach_set, fid, start)
            role = approach_set.visibility[approach_set.visibility.frame_id == fid].role.iloc[0]
            semantic = np.where(approach_set.instance_mask(fid) == 1, codes[role], 0).astype(np.int32)
            approach = (views.loc[fid].approach_of, float(views.loc[fid].approach_distance)) \
                if fid in views.index else None
            with pytest.raises(RecordingError, match="approach .* must be \\(an object of the episode"):
                recorder.record(dict(rgb=approach_set.image(fid), semantic=semantic, **sensors), camera_pitch=pitch,
                                approach=("nobody", 1.0))
            recorder.record(dict(rgb=approach_set.image(fid), semantic=semantic, depth=approach_set.depth(fid),
                                 **sensors), camera_pitch=pitch, approach=approach)
    imported = import_recording(tmp_path / "rec", approach_set.root, tmp_path / "imported")
    columns = ["step", "approach_of", "approach_distance"]
    assert imported.approach_views[columns].reset_index(drop=True).equals(views[columns].reset_index(drop=True))
    policy = ApproachVerify(distance=1.0, sigma2=0.6)
    scores = [0.9, 0.0, 0.9, 0.2], [0.8, 0.3, 0.4, 0.85]
    want, got = (episodes_at(EvalContext(fs).placements(approach_table(fs, *scores), "val"), 0.5, policy).iloc[0]
                 for fs in (approach_set, imported))
    assert (got.outcome, got.steps, got.rejections) == (want.outcome, want.steps, want.rejections) == \
        ("success", want.steps, "0:same_category:0.300")
    assert got.path == pytest.approx(want.path, abs=1e-5)


def test_the_report_says_what_was_rejected_and_when_the_steps_ran_out(approach_set, tmp_path, monkeypatch):
    """The navigation gallery names each rejected candidate (step, what its point landed on, its close score); an
    episode whose detours pass PIN's step limit says the steps ran out, not that it was still looking."""
    from pin_match.evaluation import evaluate
    from pin_match.evaluation.core import navigation
    from pin_match.evaluation.core.sigma import SigmaChoice
    from pin_match.evaluation.pages import html
    from pin_match.evaluation.pages.report_page import navigation_html

    table = approach_table(approach_set, [0.9, 0.0, 0.9, 0.2], [0.8, 0.3, 0.4, 0.85])
    policy = ApproachVerify(distance=1.0, sigma2=0.6)

    def page(folder: str) -> str:
        evaluation = evaluate(table, approach_set, SigmaChoice(0.5, "given", "test"), policy=policy)
        parts = navigation_html(approach_set, table, evaluation, 0.5, html.Assets(tmp_path / folder / "p.html", "a"))
        return " ".join(str(p) for p in parts)

    shown = page("within")
    assert "walked up to and rejected (step:point on:close score): 0:same_category:0.300" in shown
    assert "ran out" not in shown
    monkeypatch.setattr(navigation, "MAX_STEPS", 41)
    monkeypatch.setattr("pin_match.evaluation.pages.report_page.MAX_STEPS", 41)
    late = page("late")
    assert "PIN&#39;s 41 steps ran out before it stopped" in late and "still looking" not in late


def test_evaluate_decides_the_walks_once(approach_set, monkeypatch):
    """The navigation rows and the commit table read one set of decisions: the policy decides once per
    evaluation (it decided twice, once for each), and both say the same stop."""
    from pin_match.evaluation import evaluate
    from pin_match.evaluation.core.sigma import SigmaChoice

    table = approach_table(approach_set, [0.9, 0.0, 0.9, 0.2], [0.8, 0.3, 0.4, 0.85])
    calls = []
    real = ApproachVerify.decide

    def counted(self, arr, sigma, *args, **kwargs):
        calls.append(sigma)
        return real(self, arr, sigma, *args, **kwargs)

    monkeypatch.setattr(ApproachVerify, "decide", counted)
    evaluation = evaluate(table, approach_set, SigmaChoice(0.5, "given", "test"),
                          policy=ApproachVerify(distance=1.0, sigma2=0.6))
    assert calls == [0.5]
    assert list(evaluation.walks.stop_step) == list(evaluation.commits.commit_step)
