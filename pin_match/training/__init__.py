"""Training: frozen patch features stored once, a projection head learned on the train split against look-alikes.

``features`` builds the store, ``data`` / ``loss`` / ``loop`` train the head (``checkpoint``
writes it and the resume state), ``store_scores`` scores from the store, learned vs frozen. The
``learned`` matcher loads the result through ``pin_match.nn``; scoring never knows a head
was trained.
"""

from pin_match.training.config import Backbone, TrainConfig, TrainingError, default_backbone
from pin_match.training.features import FeatureStore, FeatureStoreError, build_features
from pin_match.training.loop import find_store, train
from pin_match.training.store_scores import compare_with_frozen, scored_from_store, sigma_on_split, store_frame_scores

__all__ = ["Backbone", "FeatureStore", "FeatureStoreError", "TrainConfig", "TrainingError", "build_features",
           "compare_with_frozen", "default_backbone", "find_store", "scored_from_store", "store_frame_scores",
           "train", "sigma_on_split"]
