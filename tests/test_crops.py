"""PIN's two-crop policy, generalised, and the mapping of points back into the frame."""

import numpy as np
import pytest

from pin_match.contract.crops import Crop, crop_boxes
from pin_match.contract.matcher import MatchResult, merge_crop_results


def test_pin_policy_on_a_pin_frame_is_rows_0_360_and_280_640():
    assert crop_boxes(640, 360) == [Crop(0, 0, 360, 360), Crop(0, 280, 360, 360)]


@pytest.mark.parametrize("h, w, expected", [
    (360, 640, [Crop(0, 0, 360, 360), Crop(280, 0, 360, 360)]),   # landscape: along the columns
    (300, 300, [Crop(0, 0, 300, 300)]),                             # square: one crop
    (1000, 300, [Crop(0, 0, 300, 300), Crop(0, 233, 300, 300), Crop(0, 467, 300, 300), Crop(0, 700, 300, 300)]),
    (517, 333, [Crop(0, 0, 333, 333), Crop(0, 184, 333, 333)]),
])
def test_pin_policy_generalises_and_covers_the_frame(h, w, expected):
    boxes = crop_boxes(h, w)
    assert boxes == expected
    covered = np.zeros((h, w), bool)
    for b in boxes:
        covered[b.y0:b.y0 + b.height, b.x0:b.x0 + b.width] = True
    assert covered.all()


def test_whole_policy_and_unknown_policy():
    assert crop_boxes(640, 360, "whole") == [Crop(0, 0, 360, 640)]
    with pytest.raises(ValueError, match="unknown crop policy 'tiles'"):
        crop_boxes(640, 360, "tiles")


def test_merge_takes_max_over_crops_and_maps_points_into_the_frame():
    boxes = crop_boxes(640, 360)
    parts = [MatchResult(score=0.3, points=[[10, 20]], point_scores=[0.3]),
             MatchResult(score=0.8, points=[[10, 20], [5, 0]], point_scores=[0.8, 0.1])]
    merged = merge_crop_results(parts, boxes)
    assert merged.score == pytest.approx(0.8)
    assert merged.crop_scores.tolist() == pytest.approx([0.3, 0.8])
    assert merged.points.tolist() == [[10, 20], [10, 300], [5, 280]]
    assert merged.points_at(0.5).tolist() == [[10, 300]]


def test_merge_keeps_each_boxs_view_and_maps_the_box_into_the_frame():
    boxes = crop_boxes(640, 360)
    box = np.array([[0, 0, 10, 10]], np.float32)
    parts = [MatchResult(score=0.3, boxes=box, box_scores=np.array([0.3]), box_views=np.array([2])),
             MatchResult(score=0.8, boxes=box, box_scores=np.array([0.8]), box_views=np.array([1]))]
    merged = merge_crop_results(parts, boxes)
    assert merged.boxes.tolist() == [[0, 0, 10, 10], [0, 280, 10, 290]] and merged.box_views.tolist() == [2, 1]
    parts[0].box_views = None  # a view known for some boxes only is known for none
    assert merge_crop_results(parts, boxes).box_views is None
