"""Where pin_match writes when the user names no folder: one root in the working directory, a folder per kind."""

from __future__ import annotations

from pathlib import Path

RUNS = Path("pin_match_runs")
SCORES = RUNS / "scores"
FEATURES = RUNS / "features"
REPORTS = RUNS / "reports"
SIMILARITY = RUNS / "similarity"
BENCH = RUNS / "bench"
DEMO = RUNS / "demo"
