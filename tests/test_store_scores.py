"""Store-based scores (training's comparison) read against the frame-set's labels through one EvalContext."""

from __future__ import annotations

import numpy as np
import pandas as pd
import torch

from pin_match.evaluation.core import evaluator
from pin_match.evaluation.core.labels import frame_labels
from pin_match.nn.head import ProjectionHead
from pin_match.training import compare_with_frozen, scored_from_store, store_frame_scores


def test_store_scores_carry_the_labels_a_scored_table_gets(store, tiny_frameset):
    scored = scored_from_store(tiny_frameset, store, None, "frozen")
    scores = store_frame_scores(store, tiny_frameset, None)
    assert sorted(scored.frame_id) == sorted(scores.frame_id) and len(scored) > 1
    labels = frame_labels(tiny_frameset).set_index("frame_id")
    by_frame = scored.set_index("frame_id")
    pd.testing.assert_frame_equal(by_frame[labels.columns], labels.loc[by_frame.index], check_dtype=False)
    np.testing.assert_array_equal(by_frame.score[scores.frame_id].to_numpy(), scores.score.to_numpy())


def test_learned_and_frozen_are_read_against_one_set_of_labels(store, tiny_frameset, monkeypatch):
    built = []
    monkeypatch.setattr(evaluator, "frame_labels", lambda fs: built.append(fs) or frame_labels(fs))
    torch.manual_seed(3)
    untrained = ProjectionHead(store.dim, 16)  # the identity: the learned matcher is the frozen one
    out = compare_with_frozen(tiny_frameset, store, untrained, dict(frozen=0.5, learned=0.5), split="val")
    assert built == [tiny_frameset]
    assert set(out["frozen"]["scored"].split) == {"val"}
    pd.testing.assert_frame_equal(out["learned"]["scored"], out["frozen"]["scored"])
    assert out["learned"]["metrics"] == out["frozen"]["metrics"]
