"""Photo prints: real photos (CC BY 4.0) printed on the synthetic objects, as prints on mugs, bags and covers.

Rendered flat colours and drawn logos give an ImageNet-trained network little to hold on to;
a photo printed on an object gives it natural image content, and siblings whose prints differ
differ as real merchandise does. The prints (``prints/``, listed with sources and licences in
``prints/prints.csv``) are cut-outs of the CORe50 objects and crops of the TUM RGB-D office
photos that pin_match already ships for its look-alike set; docs/synthetic.md has the command
that made them. Each print belongs to one split, so no print of a val object is seen in train.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from pin_match.data.compose import stable_seed

PRINTS_DIR = Path(__file__).resolve().with_name("prints")


@dataclass(frozen=True)
class Print:
    print_id: str
    file: str
    subject: str  # what the photo shows, for descriptions: "scissors", "office"


@lru_cache(maxsize=1)
def catalogue() -> tuple[Print, ...]:
    with open(PRINTS_DIR / "prints.csv", newline="") as f:
        return tuple(Print(r["print_id"], r["file"], r["subject"]) for r in csv.DictReader(f))


def for_split(split: str) -> tuple[Print, ...]:
    """The prints of one split: each print goes to train or val by a hash of its id (about half each)."""
    return tuple(p for p in catalogue() if (stable_seed("print split", p.print_id) % 2 == 0) == (split == "val"))


@lru_cache(maxsize=64)
def image(print_id: str) -> np.ndarray:
    """The print as RGBA uint8 (alpha 0 around a cut-out, 255 on a rectangular photo)."""
    entry = next(p for p in catalogue() if p.print_id == print_id)
    bgra = cv2.imread(str(PRINTS_DIR / entry.file), cv2.IMREAD_UNCHANGED)
    return cv2.cvtColor(bgra, cv2.COLOR_BGRA2RGBA)


def subject(print_id: str) -> str:
    return next(p.subject for p in catalogue() if p.print_id == print_id)
