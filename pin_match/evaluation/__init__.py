"""Evaluation: score tables and frame-sets in, PIN metrics, tuned sigmas, reports and tables out; no model.

``labels`` classifies frames from ground truth, ``metrics`` and ``sweep`` are pure
functions of scored frames, ``sigma`` and ``tuning`` choose the threshold, ``evaluator``,
``report``, ``tables`` and ``plots`` present it; ``bench`` runs the whole chain for several
matchers and ``demo`` for each demo set; ``similarity`` is the paper's intra/inter-category
analysis. ``EvalContext`` (a frame-set, its labels built once, the bootstrap options) is what a
run passes down where a single call takes a frame-set.
"""

from pin_match.evaluation.evaluator import (
    EvalContext,
    EvaluationError,
    check_frameset,
    evaluate,
    split_frames,
    table_subset,
)
from pin_match.evaluation.metrics import Bootstrap
from pin_match.evaluation.report import report
from pin_match.evaluation.sigma import SigmaChoice, SigmaError, load_threshold, resolve_sigma
from pin_match.evaluation.sweep import sweep
from pin_match.evaluation.tuning import DEFAULT_OBJECTIVE, OBJECTIVES, TuningError, tune, write_thresholds

__all__ = ["DEFAULT_OBJECTIVE", "OBJECTIVES", "Bootstrap", "EvalContext", "EvaluationError", "SigmaChoice",
           "SigmaError", "TuningError",
           "check_frameset", "evaluate", "load_threshold", "report", "resolve_sigma", "split_frames", "sweep",
           "table_subset", "tune", "write_thresholds"]
