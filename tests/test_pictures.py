"""The pictures the pages share: a cohort member whose image is gone is named where its picture would be."""

from __future__ import annotations

import numpy as np

from pin_match import atomic
from pin_match.contract.cohort import TargetCohort
from pin_match.evaluation.pages import html
from pin_match.evaluation.pages.pictures import cohort_members


def test_a_cohort_member_without_its_image_is_named_not_dropped(tmp_path):
    folder = tmp_path / "cohort"
    atomic.write_image(folder / "m0.png", np.full((40, 40, 3), 200, np.uint8))  # m1.png is not on this machine
    cohort = TargetCohort.of(str(folder), ["m2.png", "m0.png", "m1.png"], [0.1, 0.8, 0.6], k=2, min_std=0.25,
                             probability=True)
    strip = str(cohort_members(html.Assets(tmp_path / "page.html", "files"), cohort, n=2))
    assert strip.count("<img ") == 1 and 'alt="cohort member m0.png, raw score 0.800"' in strip
    assert f"cohort member m1.png, raw score 0.600: no image at {folder / 'm1.png'} on this machine" in strip
    assert "m2.png" not in strip  # the third closest: beyond n
    assert sorted(p.name for p in (tmp_path / "files").iterdir()) == ["0000.jpg"]
