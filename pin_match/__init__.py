"""pin_match: matchers for Personalized Instance-based Navigation, benchmarked offline.

The layers, each a subpackage that imports only those before it: ``contract`` (what a
matcher is) <- ``nn``, ``data`` <- the plug-ins in ``pin_match.matchers`` (the top-level
``matchers/`` folder) <- ``scoring`` <- ``evaluation`` <- ``training``, ``pin_agent`` <- ``cli`` (docs/architecture.md).
``import pin_match`` loads the contract only (numpy); ``FrameSet`` (pandas) loads on first use.
"""

from pin_match.contract import (
    ConfigError,
    Crop,
    CropConfig,
    CropMatcher,
    Matcher,
    MatcherConfig,
    MatcherError,
    MatchResult,
    Modality,
    Target,
    check_matcher,
    create_matcher,
    crop_boxes,
    list_matchers,
    register_matcher,
)
from pin_match.errors import PinMatchError

__version__ = "0.1.0"

__all__ = [
    "ConfigError", "Crop", "CropConfig", "CropMatcher", "FrameSet", "FrameSetError", "MatchResult", "Matcher",
    "MatcherConfig", "MatcherError", "Modality", "PinMatchError", "Target", "check_matcher", "create_matcher",
    "crop_boxes", "list_matchers", "register_matcher",
]

_LAZY = {"FrameSet": "pin_match.data.frameset", "FrameSetError": "pin_match.data.frameset"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'pin_match' has no attribute {name!r}")
