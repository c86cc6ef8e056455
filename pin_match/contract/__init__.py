"""The matcher contract: all that a matcher plug-in imports (numpy and the standard library underneath).

``prepare(target)`` once, ``match(image)`` many times; a matcher knows nothing of frame-sets,
metrics or thresholds. Built-in and third-party matchers alike take every name they use
from here.
"""

from pin_match.contract.crops import POLICIES, Crop, crop_boxes
from pin_match.contract.frames import Frames
from pin_match.contract.matcher import (
    N_DESCRIPTIONS,
    N_VIEWS,
    ConfigError,
    CropConfig,
    CropMatcher,
    Matcher,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    Target,
    TargetError,
    crops_field,
    merge_crop_results,
    weights_field,
)
from pin_match.contract.preset import Preset
from pin_match.contract.registry import (
    ENTRY_POINT_GROUP,
    RegistrationError,
    UnknownMatcherError,
    available_names,
    build_config,
    create_matcher,
    get_matcher_class,
    list_matchers,
    parse_overrides,
    register_matcher,
    with_weights,
)
from pin_match.contract.results import points_above
from pin_match.contract.testing import ContractError, check_matcher
from pin_match.contract.weights import (
    WeightsError,
    WeightsSpec,
    content_digest,
    load_torch_state,
    misfit,
    read_state_dict,
    resolve_all,
)
from pin_match.errors import PinMatchError

__all__ = [
    "ENTRY_POINT_GROUP", "N_DESCRIPTIONS", "N_VIEWS", "POLICIES", "ConfigError", "ContractError", "Crop", "CropConfig",
    "CropMatcher", "Frames", "MatchResult", "Matcher", "MatcherConfig", "MatcherError", "Modality", "PinMatchError",
    "Preset", "RegistrationError", "Target", "TargetError", "UnknownMatcherError", "WeightsError", "WeightsSpec",
    "available_names", "build_config", "check_matcher", "content_digest", "create_matcher", "crop_boxes", "crops_field",
    "get_matcher_class", "list_matchers", "load_torch_state", "merge_crop_results", "misfit", "parse_overrides",
    "points_above", "read_state_dict", "register_matcher", "resolve_all", "weights_field", "with_weights",
]
