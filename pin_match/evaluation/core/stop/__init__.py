"""When an agent that watches a sequence of frames declares the target found: the stop policies.

Every policy is a ``StopPolicy``: a frame *counts* when its score reaches its line, and the
policy *fires* when at least ``k`` of the last ``n`` frames of the episode count (a window never
reaches into the previous episode). PIN's rule is 1-of-1 with the line at sigma. A
``HouseStop`` raises each frame's line to the house's own level plus a margin: the level is the
mean of the highest scores of the episode's earlier frames, the objects this agent saw in this
house before (look-alikes included), so the decision is relative to the house and causal (frame t
reads only frames before it). A ``LookFurther`` policy does not commit at its first firing: it
walks on for a window of frames, remembers every candidate it sees and commits to the best one,
because within a house the target outscores its look-alikes far more reliably than one sigma
separates them across houses.

``decide`` is what every policy answers, per episode: where the window opened, where the agent
stopped looking, which frame it committed to and the candidates it weighed (``Decision``), given
which candidates can be placed in the house (the navigation estimate says; without geometry every
one can). A window that reaches past the last frame has not closed: the agent is still looking
when the recording ends, as it would be live (``PinDetector`` runs the same ``decide`` on the walk
so far). Only ``look:rest``, the upper bound, reads where the recording ends. ``found_frames``
(the frames where the policy fires; for a look-further policy the frame it commits to and every
firing after the commit) is what PIN's metrics read (``policy_metrics``, ``carry``); ``navigation``
reads the decisions; ``episode_stops`` says per episode where the line was and why.
Definitions: docs/metrics.md, "Stop policies".
"""

from pin_match.evaluation.core.stop.approach import ApproachVerify
from pin_match.evaluation.core.stop.base import (
    DEFAULT_POLICY,
    FIRST_MATCH,
    POLICY_SYNTAX,
    UPPER_BOUND,
    CloseLook,
    Decision,
    Placeable,
    PolicyError,
    StopPolicy,
    Verify,
    committed_found,
    episode_bounds,
    fired_arrays,
    found_frames,
    gated_scores,
    latest_counted,
    one_walk,
)
from pin_match.evaluation.core.stop.house import HouseStop
from pin_match.evaluation.core.stop.levels import RunningLevel, episode_starts, house_level
from pin_match.evaluation.core.stop.look import LookFurther

__all__ = ["DEFAULT_POLICY", "FIRST_MATCH", "POLICY_SYNTAX", "UPPER_BOUND", "ApproachVerify", "CloseLook", "Decision",
           "HouseStop", "LookFurther", "Placeable", "PolicyError", "RunningLevel", "StopPolicy", "Verify",
           "committed_found", "episode_bounds", "episode_starts", "fired_arrays", "found_frames", "gated_scores",
           "house_level", "latest_counted", "one_walk"]
