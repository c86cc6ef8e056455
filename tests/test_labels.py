"""The labelling rule: one frame class by PIN's precedence, and equal weight per fit class."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pin_match.evaluation.core.labels import CM, GM, OM, TM, UNUSED, class_weights, frame_classes
from pin_match.evaluation.core.metrics import frame_arrays
from pin_match.evaluation.pages.gallery import frame_roles
from pin_match.fitting.fusion import fit_classes
from pin_match.fitting.logistic import FitError

# every combination of the three visibility flags, and the class PIN's precedence gives it
FLAGS = [(t, s, o) for t in (True, False) for s in (True, False) for o in (True, False)]
EXPECTED = [TM, TM, TM, TM, CM, CM, GM, OM]


def labelled(flags: list[tuple[bool, bool, bool]]) -> pd.DataFrame:
    t, s, o = zip(*flags)
    n = len(flags)
    return pd.DataFrame(dict(frame_id=[f"f{i}" for i in range(n)], episode_id="e", step=range(n),
                             target_category="mug", target_visible=t, same_visible=s, other_visible=o,
                             target_seen=np.nan, score=np.linspace(0, 1, n)))


def test_the_target_wins_then_the_lookalike_then_any_other_object():
    frames = labelled(FLAGS)
    assert frame_classes(frames).tolist() == EXPECTED
    # the metrics and the galleries read the same rule
    assert frame_arrays(frames).cls.tolist() == EXPECTED
    assert frame_roles(frames).tolist() == ["target"] * 4 + ["same-category look-alike"] * 2 + ["other", "nothing"]


def test_each_fit_class_weighs_one_by_hand():
    # 1 target, 2 look-alike, 3 other (2 GM + 1 OM), 1 left out
    weights, counts = class_weights(np.array([TM, CM, CM, GM, GM, OM, UNUSED]))
    assert counts == {"target": 1, "same_category": 2, "other": 3}
    assert weights.tolist() == pytest.approx([1.0, 0.5, 0.5, 1 / 3, 1 / 3, 1 / 3, 0.0])


def test_an_empty_class_adds_no_weight():
    weights, counts = class_weights(np.array([TM, TM, OM]))
    assert counts == {"target": 2, "same_category": 0, "other": 1}
    assert weights.tolist() == [0.5, 0.5, 1.0]


def test_the_fusion_fit_labels_the_target_positive_and_refuses_a_one_sided_split():
    y, weights, counts = fit_classes(labelled(FLAGS))
    assert y.tolist() == [1.0] * 4 + [0.0] * 4
    assert weights.tolist() == pytest.approx([0.25] * 4 + [0.5, 0.5, 0.5, 0.5])
    assert counts == {"target": 4, "same_category": 2, "other": 2}
    with pytest.raises(FitError, match=r"fusion fit needs target rows .*'target': 0"):
        fit_classes(labelled([(False, True, False), (False, False, False)]))
