"""The synthetic generator: determinism, splits, references, descriptions and exact ground truth."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pin_match.data.synth import CATEGORIES, SynthSize, generate
from pin_match.data.synth.objects import make_objects

SMALL = SynthSize(seed=3, episodes=4, objects_per_category=4, frames_per_episode=8)


def tree_hash(root: Path) -> str:
    """sha256 over every file's relative path and bytes."""
    h = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("synth") / "fs", SMALL, workers=2)


def test_same_seed_same_bytes_whatever_the_workers(synth, tmp_path):
    again = generate(tmp_path / synth.root.name, SMALL, workers=1)  # same leaf: the name is in the manifest
    assert tree_hash(again.root) == tree_hash(synth.root)
    assert again.fingerprint == synth.fingerprint


def test_other_seed_other_objects():
    a = make_objects(0, 4)
    b = make_objects(1, 4)
    assert [s.look for s in a] != [s.look for s in b]
    assert [s.look for s in a] == [s.look for s in make_objects(0, 4)]


def test_splits_disjoint_and_complete(synth):
    objects = synth.objects
    train = set(objects[objects.split == "train"].object_id)
    val = set(objects[objects.split == "val"].object_id)
    assert train and val and not train & val
    for split in ("train", "val"):
        assert set(objects[objects.split == split].category) == set(CATEGORIES)
    split_of = dict(zip(objects.object_id, objects.split))
    for _, ep in synth.episodes.iterrows():
        assert {split_of[o] for o in [ep.target_object_id, *ep.distractor_object_ids]} == {ep.split}


def test_siblings_share_their_shape_and_differ_in_one_thing():
    specs = [s for s in make_objects(0, 10) if s.split == "val"]
    for category in CATEGORIES:
        family = [s for s in specs if s.category == category]
        base = family[0].look
        assert len({s.geometry_seed for s in family}) == 1 and len({s.look.variant for s in family}) == 1
        changed = [[f for f in ("colour", "colour2", "word", "photo") if getattr(s.look, f) != getattr(base, f)]
                   for s in family[1:]]
        assert all(len(c) == 1 for c in changed), (category, changed)
        assert {c[0] for c in changed} >= {"colour", "colour2"}, category


def test_default_split_matches_pinned_ratio():
    specs = make_objects(0, 10)
    assert sum(s.split == "val" for s in specs) == 72
    assert sum(s.split == "train" for s in specs) == 108


def test_references_have_real_alpha(synth):
    for object_id in synth.objects.object_id:
        target = synth.target(object_id)
        for view in target.views:
            alpha = view[..., 3]
            assert view.shape == (360, 480, 4)
            coverage = (alpha > 0).mean()
            assert 0.01 < coverage < 0.9, (object_id, coverage)
            assert (alpha == 0).any() and (alpha == 255).any()
            assert ((alpha > 0) & (alpha < 255)).any()  # anti-aliased edge, not a hard cut-out
        assert not np.array_equal(target.views[0], target.views[1])


def test_sibling_descriptions_differ(synth):
    objects = synth.objects
    for category, group in objects.groupby("category"):
        texts = [synth.descriptions[o] for o in group.object_id]
        for k in range(3):
            column = [t[k] for t in texts]
            assert len(set(column)) == len(column), (category, column)
        for t in texts:
            assert all(5 <= len(d.split()) <= 30 for d in t)


def test_visibility_agrees_with_masks(synth):
    vis = synth.visibility
    for frame_id in synth.frames.frame_id:
        mask = synth.instance_mask(frame_id)
        depth = synth.depth(frame_id)
        rows = vis[vis.frame_id == frame_id]
        values, counts = np.unique(mask[mask > 0], return_counts=True)
        assert sorted(rows.mask_value) == values.tolist()
        for _, row in rows.iterrows():
            ys, xs = np.nonzero(mask == row.mask_value)
            assert row.pixels == len(ys)
            assert (row.x0, row.y0, row.x1, row.y1) == (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)
            assert 0.03 < row.depth < 15
            assert np.isclose(row.depth, depth[ys, xs].mean(), atol=1e-3)


def test_frames_shape_and_roles(synth):
    assert set(zip(synth.frames.height, synth.frames.width)) == {(640, 360)}
    per_episode = synth.frames.groupby("episode_id").size()
    assert len(per_episode) == SMALL.episodes
    assert (per_episode >= SMALL.frames_per_episode).all()  # the approach runs to its end: longer, never shorter
    roles = set(synth.visibility.role)
    assert "target" in roles and "other" in roles


def _pixels(fs, role: str) -> pd.DataFrame:
    """Per frame (with its episode and step) the pixels of the largest object of ``role``."""
    vis = fs.visibility[fs.visibility.role == role].groupby("frame_id").pixels.max()
    frames = fs.frames[["frame_id", "episode_id", "step"]].set_index("frame_id")
    return frames.join(vis, how="left").fillna({"pixels": 0})


def test_every_episode_ends_beside_its_target_facing_it(synth):
    vis = synth.visibility
    for episode_id, frames in synth.frames.groupby("episode_id"):
        last = frames.sort_values("step").frame_id.iloc[-1]
        row = vis[(vis.frame_id == last) & (vis.role == "target")]
        assert len(row) == 1, f"{episode_id}: the last frame does not show the target"
        row = row.iloc[0]
        assert row.depth < 1.5, f"{episode_id}: the walk stops {row.depth:.2f} m from the target"  # 1.31 m high
        centre = (row.x0 + row.x1) / 2
        assert 0.25 * 360 < centre < 0.75 * 360, f"{episode_id}: the target is off to the side ({centre} px)"


def test_every_episode_stops_with_its_target_large_and_passes_a_lookalike(synth):
    """The stop (the arrival and the two tilt frames) shows the target large; a look-alike was seen near on the way."""
    target, same = _pixels(synth, "target"), _pixels(synth, "same_category")
    for episode_id, frames in target.groupby("episode_id"):
        stop = frames.sort_values("step").pixels.iloc[-3:]
        assert (stop >= 1000).all(), (episode_id, stop.tolist())
        assert same[same.episode_id == episode_id].pixels.max() >= 1000, episode_id


@pytest.mark.slow
def test_default_set_targets_large_and_alike_in_both_splits(default_synth):
    """The default set: every val episode shows its target at 2,000 px in 3 frames; the splits' medians within 2x."""
    from pin_match.evaluation.frameset_page import LARGE_PX, target_sizes
    from pin_match.evaluation.labels import frame_labels

    sizes = target_sizes(frame_labels(default_synth))
    assert LARGE_PX == 2000 and set(sizes.index) == {"train", "val"}
    large = sizes["episodes with 3 such frames"]
    assert large["val"] == sizes.episodes["val"], sizes.to_dict()
    assert large.sum() >= sizes.episodes.sum() - 2, sizes.to_dict()  # 2 train episodes miss: docs/synthetic.md
    assert sizes.p50.max() / sizes.p50.min() <= 2.0, sizes.p50.to_dict()


def test_episodes_have_same_category_distractors(synth):
    category = dict(zip(synth.objects.object_id, synth.objects.category))
    for _, ep in synth.episodes.iterrows():
        same = [o for o in ep.distractor_object_ids if category[o] == ep.target_category]
        other = [o for o in ep.distractor_object_ids if category[o] != ep.target_category]
        assert 1 <= len(same) <= 3
        assert 5 <= len(other) <= 10


def test_refuses_existing_output(synth):
    from pin_match.data.frameset import FrameSetError

    with pytest.raises(FrameSetError, match="already exists"):
        generate(synth.root, SMALL)


# ---------------------------------------------------------------- placement never fails (issue 14.1)
BIG = [(0.45, 0.8), (0.4, 0.7), (0.39, 0.65), (0.33, 0.94), (0.3, 0.6)] * 2 + [(0.25, 0.53), (0.19, 0.41)]


@pytest.mark.parametrize("seed", range(40))
def test_every_room_takes_twelve_large_objects(seed):
    """Sizes the surfaces of most rooms cannot hold: the floor along the walls takes the rest, validly."""
    from pin_match.data.synth.scene import _overlaps, make_room, place_objects

    room = make_room(np.random.default_rng(seed))
    spots = place_objects(room, BIG, np.random.default_rng(seed + 1000))
    assert len(spots) == len(BIG)
    for k, ((x, y, z, _), (radius, _)) in enumerate(zip(spots, BIG)):
        assert radius <= x <= room.width - radius and radius <= y <= room.depth - radius
        if z == 0.0:  # on the floor: clear of every piece of furniture
            assert not _overlaps((x - radius, y - radius, x + radius, y + radius), room.footprints, 0.0)
        for (ox, oy, oz, _), (r, _) in list(zip(spots, BIG))[:k]:
            if abs(oz - z) <= 0.05:
                assert np.hypot(x - ox, y - oy) > radius + r
    assert place_objects(room, BIG, np.random.default_rng(seed + 1000)) == spots  # still a pure function


@pytest.mark.slow
def test_seed_whose_surfaces_overflow_still_builds(tmp_path):
    """Seed 11 at this size used to stop with 'no free surface for an object of radius ...'."""
    size = SynthSize(seed=11, episodes=24, objects_per_category=2, frames_per_episode=1)
    fs = generate(tmp_path / "fs", size, workers=1)
    assert len(fs.episodes) == 24 and fs.frames.episode_id.nunique() == 24  # every episode rendered its walk


# ---------------------------------------------------------------- the approach walk, without rendering
@pytest.mark.parametrize("seed", range(6))
def test_walk_stops_within_a_metre_facing_the_target(seed):
    from pin_match.data.synth.scene import make_room, place_objects
    from pin_match.data.synth.walk import CAMERA_HEIGHT, MAX_STOP, MIN_STAND, Goal, camera_walk

    room = make_room(np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 100)
    (tx_, ty, tz, _), (lx, ly, lz, _) = place_objects(room, [(0.05, 0.1), (0.05, 0.1)], rng)
    target, lookalike = Goal(tx_, ty, tz + 0.05, 0.006), Goal(lx, ly, lz + 0.05, 0.006)
    poses = camera_walk(room, list(room.footprints), target, [lookalike], 20, rng)
    assert len(poses) >= 20
    x, y, yaw, pitch = poses[-1]
    assert MIN_STAND - 0.1 <= np.hypot(x - tx_, y - ty) <= MAX_STOP + 0.1  # on the floor, as PIN's success
    assert abs(np.angle(np.exp(1j * (np.arctan2(ty - y, tx_ - x) - yaw)))) < np.radians(5)  # facing it
    assert pitch == pytest.approx(np.arctan2(target.z - CAMERA_HEIGHT, np.hypot(tx_ - x, ty - y)))
    passes = [np.hypot(px - lx, py - ly) for px, py, _, _ in poses]
    assert min(passes) < 1.5  # the walk went near the look-alike


def test_prints_of_val_objects_never_print_on_train_objects():
    specs = make_objects(0, 10)
    photos = {split: {s.look.photo for s in specs if s.split == split and s.look.photo} for split in ("train", "val")}
    assert photos["train"] and photos["val"] and not photos["train"] & photos["val"]
