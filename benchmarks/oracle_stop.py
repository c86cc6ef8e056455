"""The walk's ceiling: ``python -m benchmarks.oracle_stop FRAMESET [--split val] [--px 1000]``.

The ground truth's scores (``evaluation.core.oracle``) under PIN's first match at ``--px`` pixels: the agent stops
at the first frame of the walk that shows the episode's target that large, its point on the target, and walks to it
as the navigation estimate does. Its SR is what a perfect matcher could reach on these
walks: the share of episodes whose tour shows the target large enough, less those the step limit cuts.
"""

from __future__ import annotations

import argparse

from pin_match.data.frameset import FrameSet
from pin_match.evaluation import EvalContext
from pin_match.evaluation.core.navigation import episodes_at, metrics_of
from pin_match.evaluation.core.oracle import oracle_table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frameset")
    parser.add_argument("--split", default="val")
    parser.add_argument("--px", type=int, default=1000)
    a = parser.parse_args()
    fs = FrameSet.load(a.frameset)
    height, width = fs.frames[["height", "width"]].iloc[0]
    rows = episodes_at(EvalContext(fs).placements(oracle_table(fs, "target"), a.split), a.px / (height * width))
    metrics = metrics_of(rows)
    print(f"oracle at >= {a.px} px on {a.split} ({len(rows)} episodes): SR {metrics['sr']:.1f} %, SPL "
          f"{metrics['spl']:.1f}, Steps {metrics['steps']:.1f}, not found {metrics['not_found_pct']:.1f} %")
    print(rows.outcome.value_counts().to_string())


if __name__ == "__main__":
    main()
