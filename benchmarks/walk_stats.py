"""What a synthetic set's walks are like: ``python -m benchmarks.walk_stats FRAMESET [--split val]``.

Per split: frames of the walk per episode, approach views per episode (what an agent sees walking
up to each object, after the walk), and frames rendered per episode (a house's walk and approach
views rendered once for its episodes), the start-to-target geodesic, the share of episodes starting
in another room than the target, and, over the episodes whose target is seen at ``SEEN_PX`` pixels
or more, the share where a same-family look-alike is first seen so before the target and where the
target is first seen in the first half of the walk (issue 64's checks; docs/synthetic.md).

Then what the tour of the whole house does (``tour``): the share of episodes whose walk shows the target at
all and at ``LARGE_PX`` pixels or more (a small product seen close), per house the rooms its walk enters
(``Room.room_of`` of every pose) and the walk's frames. Approach views (older sets) are left out of all of it.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from pin_match.data.compose import stable_seed
from pin_match.data.frameset import FrameSet

SEEN_PX = 1000
LARGE_PX = 2000  # a 10-30 cm product on furniture seen from within about 1-1.5 m (the tour's aim)


def first_seen(fs: FrameSet, episode_id: str, role: str) -> int | None:
    """The first step of the episode's walk where an object of ``role`` shows ``SEEN_PX`` pixels or more."""
    vis = fs.visibility[(fs.visibility.role == role) & (fs.visibility.pixels >= SEEN_PX)
                        & ~fs.visibility.frame_id.isin(fs.approach_views.frame_id)]
    steps = fs.frames.set_index("frame_id").loc[vis.frame_id, ["episode_id", "step"]]
    steps = steps[steps.episode_id == episode_id].step
    return int(steps.min()) if len(steps) else None


def houses_of(fs: FrameSet) -> dict:
    """Each house of the set (``scene_id``) as its scene seed rebuilds it (``scene.make_house``)."""
    from pin_match.data.synth.scene import make_house

    provenance = fs.manifest["provenance"]
    seed, rooms = int(provenance["seed"]), int(provenance["rooms"])
    return {house_id: make_house(np.random.default_rng(stable_seed(seed, "scene", house_id)), rooms)
            for house_id in sorted(set(fs.episodes.scene_id))}


def rooms_of(fs: FrameSet, houses: dict) -> dict[str, tuple[int, int]]:
    """Per episode, (room of the start, room of the target)."""
    out = {}
    for episode_id, house_id, target in zip(fs.episodes.episode_id, fs.episodes.scene_id,
                                            fs.episodes.target_object_id):
        geometry = fs.geometry.episodes[episode_id]
        tx, ty, _ = geometry.positions[target]
        house = houses[house_id]
        out[episode_id] = (house.room_of(geometry.start.x, geometry.start.y), house.room_of(tx, ty))
    return out


def tour(fs: FrameSet, houses: dict) -> dict:
    """How the walks cover their houses: per episode the target's largest view in the walk (pixels, 0 where never
    shown), and per house the rooms its walk enters and its frames (every episode of a house reads one walk, so the
    house's first episode stands for it)."""
    walk = fs.frames[~fs.frames.frame_id.isin(fs.approach_views.frame_id)]
    target = fs.visibility[(fs.visibility.role == "target") & fs.visibility.frame_id.isin(walk.frame_id)]
    largest = target.merge(walk[["frame_id", "episode_id"]]).groupby("episode_id").pixels.max()
    largest = largest.reindex(fs.episodes.episode_id, fill_value=0)
    first = walk[walk.episode_id.isin(fs.episodes.groupby("scene_id").episode_id.first())]
    first = first.merge(fs.episodes[["episode_id", "scene_id"]])
    entered = {house_id: len({houses[house_id].room_of(x, y) for x, y in zip(rows.pose_x, rows.pose_y)})
               for house_id, rows in first.groupby("scene_id")}
    per_house = first.groupby("scene_id").size()
    return dict(target_shown_pct=100 * float((largest > 0).mean()),
                target_large_pct=100 * float((largest >= LARGE_PX).mean()),
                target_px_median=float(largest.median()),
                houses_every_room_pct=100 * float(np.mean([entered[h] == len(houses[h].rooms) for h in entered])),
                rooms_entered_min=min(entered.values()),
                walk_frames_per_house_min_mean_max=[int(per_house.min()), float(per_house.mean()),
                                                    int(per_house.max())])


def rendered(fs: FrameSet, per_episode) -> int:
    """Frames rendered: an exploration walk once per house, a walk that heads for its target once per episode."""
    if fs.manifest["provenance"].get("walk") != "explore":
        return int(per_episode.sum())
    house = fs.episodes.set_index("episode_id").scene_id
    return int(per_episode.groupby(house.loc[per_episode.index].to_numpy()).first().sum())


def stats(fs: FrameSet) -> dict:
    views = fs.approach_views
    per_episode = fs.frames[~fs.frames.frame_id.isin(views.frame_id)].groupby("episode_id").size()
    approach = views.groupby("episode_id").size().reindex(per_episode.index, fill_value=0)
    houses = fs.episodes.groupby("scene_id").size()
    geodesic = np.array([fs.geometry.episodes[e].geodesic_distance for e in fs.episodes.episode_id])
    houses = houses_of(fs)
    rooms = rooms_of(fs, houses)
    seen = lookalike_first = early = 0
    for episode_id, frames in per_episode.items():
        target = first_seen(fs, episode_id, "target")
        if target is None:
            continue
        seen += 1
        lookalike = first_seen(fs, episode_id, "same_category")
        lookalike_first += lookalike is not None and lookalike < target
        early += target < frames / 2
    return dict(episodes=len(per_episode), houses=len(houses), frames=int(per_episode.sum() + approach.sum()),
                frames_per_episode=float(per_episode.mean()), approach_views_per_episode=float(approach.mean()),
                rendered_per_episode=rendered(fs, per_episode + approach) / len(per_episode),
                geodesic_min_median_max=[float(geodesic.min()), float(np.median(geodesic)), float(geodesic.max())],
                other_room_pct=100 * float(np.mean([a != b for a, b in rooms.values()])),
                target_seen=seen, lookalike_first_pct=100 * lookalike_first / max(seen, 1),
                target_in_first_half_pct=100 * early / max(seen, 1), tour=tour(fs, houses))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frameset")
    parser.add_argument("--split", default=None)
    a = parser.parse_args()
    fs = FrameSet.load(a.frameset)
    print(json.dumps(stats(fs.split(a.split) if a.split else fs), indent=1))


if __name__ == "__main__":
    main()
