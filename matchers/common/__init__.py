"""What several plug-ins share: backbones, patch and feature-map scoring, the EfficientNet matchers' network, cells as
parts, keypoints and their references, SuperPoint, kornia's networks, composites, candidate boxes and the fitted files
(what a matcher and ``pin_match.fitting`` both read). No module here registers a matcher, and no plug-in imports
another."""
