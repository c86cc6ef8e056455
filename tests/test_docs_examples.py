"""The matchers the docs show run as printed: a newcomer's first matcher and the example file pass the contract."""

from __future__ import annotations

import re
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np

from pin_match.contract import Target, check_matcher, create_matcher, list_matchers, registry

ROOT = Path(__file__).parents[1]
DOC = ROOT / "docs" / "adding-a-matcher.md"


def test_shortest_matcher_in_the_docs_passes_the_contract():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    assert len(blocks) >= 2
    namespace: dict = {}
    exec(compile("\n".join(blocks[:2]), str(DOC), "exec"), namespace)  # the second block calls check_matcher
    assert create_matcher("my-matcher").id.startswith("my-matcher@")


def test_the_example_file_works_as_a_plug_in_and_is_no_built_in(monkeypatch, own_registry):
    """examples/my_matcher.py, declared as a third-party package would (an entry point), passes the contract."""
    assert "example-mean-color" not in list_matchers()
    monkeypatch.syspath_prepend(str(ROOT / "examples"))
    ep = EntryPoint(name="example-mean-color", value="my_matcher:MeanColorMatcher", group=registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "_entry_points", lambda: {ep.name: ep})
    assert "example-mean-color" in list_matchers("example-*")
    scores = check_matcher("example-mean-color")
    assert all(0.0 <= s <= 1.0 for s in scores.values())  # one minus a colour distance scaled by its maximum
    assert create_matcher("example-mean-color", grid=4).cfg.grid == 4


def test_a_variant_in_the_docs_is_a_preset_of_the_first_matcher(own_registry):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    variant = next(b for b in blocks if "preset=" in b)
    namespace: dict = {}
    exec(compile(blocks[0] + "\n" + variant, str(DOC), "exec"), namespace)
    whole = create_matcher("my-matcher-whole")
    assert (whole.cfg.crops, whole.default_sigma) == ("whole", -40.0)
    assert create_matcher("my-matcher").cfg.crops == "pin"
    frame = np.zeros((60, 100, 3), np.uint8)
    view = np.full((8, 8, 4), 255, np.uint8)
    target = Target("x", "toy", (view,) * 3, ("a", "b", "c"))
    whole.prepare(target)
    assert len(whole.match(frame).crop_scores) == 1  # the whole frame, one crop
