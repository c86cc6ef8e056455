"""What several plug-ins share: backbones, patch and feature-map scoring, keypoints and their references, SuperPoint,
kornia's networks, composites, candidate boxes and fitted files. No module here registers a matcher."""
