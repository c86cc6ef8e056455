"""Object instances: real scanned products in look-alike families, with the descriptions written from their names.

A family is one kind of product (the frame-set's category): ink-cartridge boxes of one retailer,
white supplement bottles, one planter in several colours. Its members differ from each other in
their print, their colour or their shape, as the look-alikes a PIN agent meets do. Families,
splits and kinds of difference come from the scan folder's ``families.csv`` (chosen by eye from
renders of every scan; docs/synthetic.md has the table), so no instance is in two splits by
construction. An instance is fully described by its ``ObjectSpec``, so worker processes load its
scan from the spec instead of receiving arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pin_match.data.synth.scans import Scan, ScanFolder, load_scan
from pin_match.errors import PinMatchError


class SynthError(PinMatchError, ValueError):
    """Generator settings that cannot make a frame-set (too few episodes, objects or frames)."""


@dataclass(frozen=True)
class ObjectSpec:
    """One instance: its id, family (category), split, scan (its mesh and texture files in the folder ``folder``)
    and how it differs."""

    object_id: str
    category: str
    split: str
    scan: str
    difference: str
    folder: str
    files: tuple[str, str]  # mesh, texture (scans.csv's columns), so a worker loads the scan without the tables
    source: str
    licence: str
    descriptions: tuple[str, ...]

    def load(self) -> Scan:
        return load_scan(Path(self.folder), self.scan, *self.files)


def _is_tag(word: str) -> bool:
    """GSO's 11-character tags that tell apart scans of one product name ("BjTLbuRVt1t", "MFWkmoweejt"), not a
    capitalised word of the name ("Lactoferrin")."""
    return (len(word) == 11 and word.isalnum() and any(c.islower() for c in word)
            and any(c.isdigit() or c.isupper() for c in word[1:]))


def title(scan: str) -> str:
    """The product's name as a person would read it off the scan's name ("Poppin File Sorter Blue")."""
    words = scan.split("_")
    return " ".join(words[:-1] if len(words) > 1 and _is_tag(words[-1]) else words)


def describe(family: str, scan: str) -> tuple[str, str, str]:
    """Three descriptions naming the kind of product and the product itself, as a user would name their own."""
    name = title(scan)
    article = "an" if family[0] in "aeiou" else "a"
    return (f"{article} {family}: {name}", f"the {family} that is the {name}", f"look for my {name} {family}")


def make_objects(folder: ScanFolder, per_family: int) -> list[ObjectSpec]:
    """The instances of every family, at most ``per_family`` of each family in each split (in table order)."""
    if per_family < 2:
        raise SynthError(f"objects_per_family must be at least 2 (a target and a look-alike), got {per_family}")
    taken: dict[tuple[str, str], int] = {}
    specs = []
    for m in folder.members:
        key = (m.family, m.split)
        if taken.get(key, 0) >= per_family:
            continue
        taken[key] = taken.get(key, 0) + 1
        row = folder.scans[m.scan]
        specs.append(ObjectSpec(m.scan, m.family, m.split, m.scan, m.difference, str(folder.root),
                                (row["mesh"], row["texture"]), row["source"], row["licence"],
                                describe(m.family, m.scan)))
    return specs
