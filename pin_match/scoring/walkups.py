"""The closed loop's walk-ups, scored on demand: render what the agent would see walking up, score it once.

The decisions ask for the views of each candidate an agent walks up to (``views``); a view not scored yet is
asked for and the decision waits. ``resolve`` then renders every view asked for in the set's houses
(``data.synth.walkups``, each view once, kept by pose) and scores them as one frame-set through the engine
(``run_jobs``: chunks, resume, the cache by matcher and frame-set), so a view is scored once per matcher and
target, and every decision already made reads the same numbers again: score once, decide many times.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace
from pathlib import Path

from pin_match import outputs
from pin_match.contract.matcher import Matcher
from pin_match.data.frameset import FrameSet
from pin_match.data.synth.size import made_by_generator
from pin_match.data.walkup import Pose, WalkUp, pose_key
from pin_match.scoring.api import run_jobs
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.product import Job
from pin_match.scoring.table import ScoreTable

WALKUPS = "walkups"  # the folder under the scores' root: views by pose, and the walk-up sets


class RenderedWalkUps:
    """One matcher's scores of the walk-up views of a synthetic set's episodes, rendered and scored on demand."""

    def __init__(self, fs: FrameSet, matcher: Matcher, out: str | Path = outputs.SCORES,
                 run: RunOptions = DEFAULT_RUN) -> None:
        self.root = Path(out) / WALKUPS / fs.fingerprint
        self.fs, self.matcher, self.out = fs, matcher, out
        self.run = replace(run, progress=False)  # a round of walk-ups is a moment of a decision: no bar of its own
        self._houses = None
        self.scores: dict[tuple[str, str], float] = {}
        self.pending: dict[str, dict[str, Pose]] = {}

    def views(self, episode_id: str, walkup: WalkUp, within: float) -> tuple[tuple[float, float], ...] | None:
        """(distance, score) of each view an approach-verify policy with distance ``within`` reads
        (``WalkUp.needed``); None while one of them is not scored yet (it is asked for: ``resolve``)."""
        needed = walkup.needed(within)
        keys = [pose_key(walkup.poses[k]) for k in needed]
        missing = {key: walkup.poses[k] for k, key in zip(needed, keys) if (episode_id, key) not in self.scores}
        if missing:
            self.pending.setdefault(episode_id, {}).update(missing)
            return None
        return tuple((walkup.distances[k], self.scores[(episode_id, key)]) for k, key in zip(needed, keys))

    def resolve(self) -> bool:
        """Render and score every view asked for since the last call; False when nothing was asked for."""
        from pin_match.data.synth.walkups import SynthHouses, request_name, write_walkup_set  # pybullet loads here

        if not self.pending:
            return False
        if self._houses is None:  # staged the first time a view is rendered: a set decided without one needs none
            self._houses = SynthHouses(self.fs, self.root / "views")
        requests: Mapping[str, list[Pose]] = {e: list(poses.values()) for e, poses in self.pending.items()}
        walk_fs = write_walkup_set(self._houses, requests, self.root / "sets" / request_name(self.fs, requests))
        table = ScoreTable.read(run_jobs(walk_fs, [Job(self.matcher)], out=self.out, run=self.run)[0])
        keys = {e: sorted(self.pending[e]) for e in self.pending}  # a walk-up set's frames are in key order
        for episode_id, step, score in zip(table.frames.episode_id, table.frames.step, table.frames.score):
            self.scores[(str(episode_id), keys[str(episode_id)][int(step)])] = float(score)
        self.pending.clear()
        return True

    @property
    def scored(self) -> int:
        """Views scored so far (one per episode and pose)."""
        return len(self.scores)


def walkup_scorer(fs: FrameSet, matchers: Iterable[Matcher], out: str | Path = outputs.SCORES,
                  run: RunOptions = DEFAULT_RUN) -> Callable[[ScoreTable], RenderedWalkUps | None] | None:
    """For an evaluation of ``fs`` (``EvalContext(walk_ups=...)``): each table's walk-ups, scored by the matcher
    that scored the table (one of ``matchers``, by id; None for another); None where the set has no house to render
    in (a PIN recording, real photos)."""
    if not made_by_generator(fs.manifest):
        return None
    by_id = {matcher.id: matcher for matcher in matchers}
    made: dict[str, RenderedWalkUps] = {}

    def walk_ups(table: ScoreTable) -> RenderedWalkUps | None:
        matcher = by_id.get(table.matcher_id)
        if matcher is None:
            return None
        return made.setdefault(matcher.id, RenderedWalkUps(fs, matcher, out, run))

    return walk_ups
