"""Evaluation: score tables and frame-sets in, PIN metrics, tuned sigmas, reports and tables out; no model.

Three rooms, in the order a run reads them. ``core``: ``labels`` classifies frames from ground
truth, ``metrics`` and ``sweep`` are pure functions of scored frames, ``sigma`` and ``tuning``
choose the threshold, ``evaluator`` and ``tables`` state it, ``similarity`` is the paper's
intra/inter-category analysis. ``pages``: the plots, pictures and HTML pages that show it.
``flows``: ``report`` writes one matcher's folder, ``bench`` runs the whole chain for several
matchers, ``trade`` reads look-further windows side by side and ``demo`` runs each demo set. The
public path of a run is this package (``from pin_match.evaluation import bench, tune, report``)
and ``pin_match.scoring`` (``score``). ``EvalContext`` (a frame-set, its labels built once,
each scored split's arrays converted once, the bootstrap options) is what a run passes down
where a single call takes a frame-set.
"""

from pin_match.evaluation.core.evaluator import (
    EvalContext,
    EvaluationError,
    check_frameset,
    evaluate,
    split_frames,
    table_subset,
)
from pin_match.evaluation.core.metrics import Bootstrap
from pin_match.evaluation.core.policies import tune_policy
from pin_match.evaluation.core.sigma import SigmaChoice, SigmaError, load_threshold, resolve_sigma
from pin_match.evaluation.core.stop import FIRST_MATCH, ApproachVerify, HouseStop, LookFurther, StopPolicy
from pin_match.evaluation.core.sweep import sweep
from pin_match.evaluation.core.tuning import DEFAULT_OBJECTIVE, OBJECTIVES, TuningError, tune, write_thresholds
from pin_match.evaluation.flows.bench import SigmaRule, bench
from pin_match.evaluation.flows.report import report
from pin_match.evaluation.flows.trade import trade

__all__ = ["DEFAULT_OBJECTIVE", "FIRST_MATCH", "OBJECTIVES", "ApproachVerify", "Bootstrap", "EvalContext",
           "EvaluationError", "HouseStop", "LookFurther", "SigmaChoice", "SigmaError", "SigmaRule", "StopPolicy",
           "TuningError", "bench", "check_frameset", "evaluate", "load_threshold", "report", "resolve_sigma",
           "split_frames", "sweep", "table_subset", "trade", "tune", "tune_policy", "write_thresholds"]
