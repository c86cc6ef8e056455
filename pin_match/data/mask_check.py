"""The check every shipped cut-out passes, and the repair tried before a photo is dropped.

A reference view is the object under its mask, so a mask that kept the holding hand, the
wall, or only a corner of the object teaches a matcher the wrong thing. The rules below are
stated once here and applied to every photo of a source folder (``prepare_core50``) and, by
a test, to every mask shipped with pin_match:

- area: the object covers ``MIN_AREA``-``MAX_AREA`` of the photo (the sources crop around
  one hand-held object, so less is a lost object and more is background);
- border: at most ``MAX_BORDER`` of the one-pixel ring ``BORDER_BAND`` in from the photo's
  edge is on the mask. A ring, not the edge itself: ``object_mask`` seeds the outer tenth as
  background and its outermost pixels as sure background, so its masks never reach the edge
  but spread along this ring when they take the wall or the arm; a held object may cross it a
  little (a big remote control crosses 12% of it);
- one piece: after specks below ``SPECK`` of the photo are dropped, one 8-connected piece;
- hand: at most ``MAX_SKIN`` of the mask is skin-coloured (``skin_pixels``).
"""

from __future__ import annotations

import cv2
import numpy as np

from pin_match.data.compose import largest_piece

MIN_AREA, MAX_AREA = 0.03, 0.60
MAX_BORDER = 0.15
BORDER_BAND = 0.10  # of the shorter side
SPECK = 0.005
MAX_SKIN = 0.15
# skin in YCrCb (Chai & Ngan 1999): Cr 138-173 and Cb 77-127; the hands of CORe50 fall in it, few objects do
SKIN_CR, SKIN_CB = (138, 173), (77, 127)


def skin_pixels(rgb: np.ndarray) -> np.ndarray:
    """Boolean map of skin-coloured pixels (the YCrCb box above)."""
    ycrcb = cv2.cvtColor(rgb, cv2.COLOR_RGB2YCrCb)
    cr, cb = ycrcb[..., 1], ycrcb[..., 2]
    return (cr >= SKIN_CR[0]) & (cr <= SKIN_CR[1]) & (cb >= SKIN_CB[0]) & (cb <= SKIN_CB[1])


def mask_problems(rgb: np.ndarray, mask: np.ndarray, *, hand: bool = True) -> list[str]:
    """What breaks the rules above (empty when the mask passes); ``mask`` is 0/1 or 0/255, the photo's size.

    ``hand=False`` leaves out the hand rule, for sources whose objects are not held: there a
    tan dog or a pink doll is what the skin box catches, not a hand.
    """
    on = mask > 0
    h, w = on.shape
    problems = []
    area = float(on.mean())
    if not MIN_AREA <= area <= MAX_AREA:
        problems.append(f"area {area:.1%} of the photo, outside {MIN_AREA:.0%}-{MAX_AREA:.0%}")
    b = max(int(round(BORDER_BAND * min(h, w))), 1)
    ring = np.concatenate([on[b, b:w - b], on[h - 1 - b, b:w - b], on[b:h - b, b], on[b:h - b, w - 1 - b]])
    if ring.mean() > MAX_BORDER:
        problems.append(f"{ring.mean():.0%} of the ring {b} px in from the border is on the mask "
                        f"(at most {MAX_BORDER:.0%})")
    n, _, stats, _ = cv2.connectedComponentsWithStats(on.astype(np.uint8), connectivity=8)
    pieces = int((stats[1:, cv2.CC_STAT_AREA] >= SPECK * h * w).sum())
    if pieces > 1:
        problems.append(f"{pieces} pieces larger than {SPECK:.1%} of the photo")
    skin = float(skin_pixels(rgb)[on].mean()) if hand and on.any() else 0.0
    if skin > MAX_SKIN:
        problems.append(f"{skin:.0%} of the mask is skin-coloured (a hand; at most {MAX_SKIN:.0%})")
    return problems


def without_hand(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The mask (0/255) less its skin-coloured pixels, opened, as its largest piece with holes filled.

    The repair tried before a photo is dropped: GrabCut often keeps the fingers wrapped
    around the object, which the skin rule removes; opening cuts the thin bridges they leave.
    """
    on = ((mask > 0) & ~skin_pixels(rgb)).astype(np.uint8)
    on = largest_piece(cv2.morphologyEx(on, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)))
    if not on.any():
        return on
    h, w = on.shape
    outside = cv2.floodFill(on.copy() * 255, np.zeros((h + 2, w + 2), np.uint8), (0, 0), 255)[1] == 0
    return np.where((on > 0) | outside, 255, 0).astype(np.uint8)


def checked_mask(rgb: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray | None, str]:
    """The mask to keep and what happened to it: passed (``""``), repaired, or ``None`` and why it is dropped.

    A failing mask is repaired once with ``without_hand`` and checked again; one photo lost
    costs less than a reference view that teaches a hand or a wall.
    """
    problems = mask_problems(rgb, mask)
    if not problems:
        return mask, ""
    repaired = without_hand(rgb, mask)
    still = mask_problems(rgb, repaired) if repaired.any() else ["nothing left without the skin"]
    if still:
        return None, "dropped: " + "; ".join(still)
    return repaired, "repaired by removing the skin: " + "; ".join(problems)
