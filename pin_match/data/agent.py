"""PIN's agent as the benchmark models it: its camera and its actions, said once.

PIN's agent (aimagelab/pin, its habitat configuration) carries one RGB-D camera 1.31 m above the floor, 42 degrees
wide, 360 x 640 (portrait: width x height), and acts in discrete steps: forward 0.25 m, turn left or right 30
degrees, look up or down 30 degrees, stop. An episode ends after 1,000 actions.
"""

from __future__ import annotations

import math

CAMERA_HEIGHT = 1.31  # metres above the floor
HFOV_DEG = 42.0  # horizontal field of view, degrees
FRAME_HEIGHT, FRAME_WIDTH = 640, 360  # pixels: a portrait frame
HALF_HFOV = math.radians(HFOV_DEG) / 2
FOCAL_PX = FRAME_WIDTH / 2 / math.tan(HALF_HFOV)  # the pinhole's focal length in pixels (about 469)
HALF_VFOV = math.atan(FRAME_HEIGHT / 2 / FOCAL_PX)  # half the vertical field of view (about 34.3 degrees)
FORWARD_STEP = 0.25  # metres per forward action
TURN = math.radians(30.0)  # one turn action
TILT = math.radians(30.0)  # one look-up or look-down action
MAX_STEPS = 1000  # PIN's episode ends here: a stop not called within this many actions is no stop
