"""pin_match: matchers for Personalized Instance-based Navigation, benchmarked offline."""

from pin_match.crops import Crop, crop_boxes
from pin_match.frameset import FrameSet, FrameSetError
from pin_match.matcher import (
    ConfigError,
    CropConfig,
    CropMatcher,
    Matcher,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    Target,
)
from pin_match.registry import create_matcher, list_matchers, register_matcher

__version__ = "0.1.0"

__all__ = [
    "ConfigError", "Crop", "CropConfig", "CropMatcher", "FrameSet", "FrameSetError", "MatchResult", "Matcher",
    "MatcherConfig", "MatcherError", "Modality", "Target", "create_matcher", "crop_boxes", "list_matchers",
    "register_matcher",
]
