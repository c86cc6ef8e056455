"""The sigmas shipped for the demo apply to the demo sets as built now: a newcomer's demo scores val frames only.

When a change to a demo set's builder or to one of its matchers' ids makes them stale, the demo
still runs (it tunes on the train split again, minutes longer) and this test says what to redo.
"""

from __future__ import annotations

import shutil
from dataclasses import replace

import pytest

from pin_match.evaluation.flows.demo import DEMO_SETS, shipped_sigmas
from pin_match.scoring.options import RunOptions

REDO = ("rerun `pin-match demo --tune --out DIR` and copy DIR/{folder}demo_sigmas.json to "
        "pin_match/evaluation/flows/demo_sigmas/{file}")


@pytest.mark.slow
@pytest.mark.parametrize("demo_set", DEMO_SETS, ids=lambda s: s.sigmas)
def test_the_shipped_sigmas_were_tuned_on_this_set_for_these_matchers(demo_set, tmp_path):
    redo = REDO.format(folder=f"{demo_set.folder}/" if demo_set.folder else "", file=demo_set.sigmas)
    assert demo_set.shipped.is_file(), redo
    fs = demo_set.build(tmp_path / "frameset", 0, RunOptions(workers=2, progress=False))
    assert shipped_sigmas(demo_set, fs)[0] == demo_set.shipped, redo


def _built(root, provenance: dict, shade: int):
    """A two-episode set of one definition (``provenance``) whose frames' bytes depend on ``shade``, as a renderer or
    a JPEG writer on another machine would make them."""
    import numpy as np

    from conftest import make_view
    from pin_match.data.writer import Frame, FrameSetWriter

    w = FrameSetWriter(root, "demo-like", provenance=provenance)
    for oid, split in (("mug_a", "train"), ("mug_b", "val")):
        w.add_object(oid, "mug", split, [make_view((200, 30, 30))] * 3, [f"{oid} {k}" for k in range(3)])
        w.add_episode(f"ep_{split}", split, "house", oid, [])
        roles = w.roles(f"ep_{split}")
        for step in range(2):
            mask = np.zeros((64, 48), np.uint16)
            mask[10:20, 10:20] = 1
            w.write_frame(f"ep_{split}", step, Frame(np.full((64, 48, 3), shade + step, np.uint8), mask,
                                                     {1: (oid, roles[oid])}))
    return w.close()


def test_shipped_sigmas_follow_the_set_s_definition_not_its_bytes(tmp_path):
    """Issue 60.1: the same definition with other frame bytes gets the shipped sigmas; another seed, another
    generator version or another matcher id does not, and the line says why."""
    from pin_match import atomic
    from pin_match.contract.registry import create_matcher
    from pin_match.evaluation.flows.demo import SCANNED, set_definition

    provenance = dict(generator="pin_match.data.synth", version=5, seed=0, episodes=2)
    here = _built(tmp_path / "here", provenance, 90)
    there = _built(tmp_path / "there", provenance, 91)  # another machine's bytes
    assert here.fingerprint != there.fingerprint
    shipped = tmp_path / "shipped.json"
    demo_set = replace(SCANNED, matchers=("color",), sigmas=str(shipped))  # an absolute path replaces the folder
    atomic.write_json(shipped, dict(definition=set_definition(demo_set, here), frameset_fingerprint=here.fingerprint,
                                    thresholds={create_matcher("color").id: {"sigma": 0.8}}))
    assert shipped_sigmas(demo_set, there) == (shipped, "shipped (shipped.json: tuned on the train split of a set "
                                                        "of this definition)")
    for change, word in ((dict(seed=1), "seed"), (dict(version=6), "version")):
        other = _built(tmp_path / word, provenance | change, 90)
        path, why = shipped_sigmas(demo_set, other)
        assert path is None and f"another definition of the set ({word})" in why and "--tune" in why
    path, why = shipped_sigmas(replace(demo_set, matchers=("color", "sift")), there)
    assert path is None and f"not for {create_matcher('sift').id}" in why


REFUSED = ("the shipped ones were tuned on another definition of the set (content: the packaged objects or photos, or "
           "the code that renders them): tuned on its train split instead (`pin-match demo --tune` writes the table "
           "to ship)")
# per demo set, one packaged object or photo folder and one module that renders it
CONTENT = {"scanned.json": ("data/synth/gso/scans", "data/synth/render.py"),
           "lookalikes.json": ("data/sources/lookalike_src/photos", "data/sources/lookalike_set.py")}


def _flip_a_byte(path) -> bytes:
    """Change one byte of ``path`` in place; its bytes before."""
    before = path.read_bytes()
    data = bytearray(before)
    data[len(data) // 2] ^= 1
    path.write_bytes(bytes(data))
    return before


@pytest.mark.parametrize("demo_set", DEMO_SETS, ids=lambda s: s.sigmas)
def test_a_change_of_content_under_the_same_version_does_not_get_the_shipped_sigmas(demo_set, tmp_path, monkeypatch):
    """Issue 66.3: the definition digests what the builder reads, wherever the package lies and whatever its files'
    times; one byte changed in a packaged scan or photo, or in the code that renders it, under the same generator
    version, is another set: its shipped sigmas are refused with the line the demo prints."""
    from pin_match import atomic
    from pin_match.contract.registry import create_matcher
    from pin_match.evaluation.flows import demo

    package = tmp_path / "elsewhere" / "pin_match"  # copied with new times, in another folder
    shutil.copytree(demo.PACKAGE / "data", package / "data", copy_function=shutil.copy,
                    ignore=shutil.ignore_patterns("__pycache__"))
    assert demo.reads_digest(package, demo_set.reads) == demo_set.content()
    monkeypatch.setattr(demo, "PACKAGE", package)
    fs = _built(tmp_path / "set", dict(generator="pin_match.data.synth", version=6, seed=0, episodes=2), 90)
    shipped = tmp_path / "shipped.json"
    ours = replace(demo_set, matchers=("color",), sigmas=str(shipped))
    atomic.write_json(shipped, dict(definition=demo.set_definition(ours, fs),
                                    thresholds={create_matcher("color").id: {"sigma": 0.8}}))
    assert demo.shipped_sigmas(ours, fs)[0] == shipped
    folder, module = CONTENT[demo_set.sigmas]
    for changed in (sorted((package / folder).iterdir())[0], package / module):
        before = _flip_a_byte(changed)
        demo.reads_digest.cache_clear()  # read once per process: a new process would read the changed byte
        assert demo.shipped_sigmas(ours, fs) == (None, REFUSED), changed
        changed.write_bytes(before)
        demo.reads_digest.cache_clear()
        assert demo.shipped_sigmas(ours, fs)[0] == shipped


def _val_only(root, provenance: dict, shade: int, frames: int = 2):
    """``_built``'s val episode alone, as the demo renders it when the sigmas are shipped."""
    import numpy as np

    from conftest import make_view
    from pin_match.data.writer import Frame, FrameSetWriter

    w = FrameSetWriter(root, "demo-like", provenance=provenance | {"splits": ["val"]})
    w.add_object("mug_b", "mug", "val", [make_view((200, 30, 30))] * 3, [f"mug_b {k}" for k in range(3)])
    w.add_episode("ep_val", "val", "house", "mug_b", [])
    for step in range(frames):
        mask = np.zeros((64, 48), np.uint16)
        mask[10:20, 10:20] = 1
        w.write_frame("ep_val", step, Frame(np.full((64, 48, 3), shade + step, np.uint8), mask,
                                            {1: ("mug_b", "target")}))
    return w.close()


def test_the_val_split_alone_of_the_same_definition_gets_the_shipped_sigmas(tmp_path):
    """Issue 60.2: the demo renders the val split alone when its sigmas are shipped; that split is the whole set's,
    so the whole set's table applies, and a val split of another length does not."""
    from pin_match import atomic
    from pin_match.contract.registry import create_matcher
    from pin_match.evaluation.flows.demo import SCANNED, set_definition

    provenance = dict(generator="pin_match.data.synth", version=6, seed=0, episodes=2)
    whole = _built(tmp_path / "whole", provenance, 90)
    shipped = tmp_path / "shipped.json"
    demo_set = replace(SCANNED, matchers=("color",), sigmas=str(shipped))
    atomic.write_json(shipped, dict(definition=set_definition(demo_set, whole),
                                    thresholds={create_matcher("color").id: {"sigma": 0.8}}))
    assert shipped_sigmas(demo_set, _val_only(tmp_path / "val", provenance, 91))[0] == shipped
    path, why = shipped_sigmas(demo_set, _val_only(tmp_path / "longer", provenance, 91, frames=3))
    assert path is None and "another definition of the set (val)" in why


@pytest.mark.slow
def test_a_split_rendered_alone_has_the_whole_set_s_bytes(tmp_path):
    from pin_match.data.synth import SynthSize, generate

    size = SynthSize(seed=3, episodes=2, objects_per_family=2, frames_per_episode=6)
    whole = generate(tmp_path / "whole", size, workers=1)
    alone = generate(tmp_path / "alone", replace(size, splits=("val",)), workers=1)
    assert set(alone.episodes.split) == {"val"} and alone.manifest["provenance"]["splits"] == ["val"]
    val = whole.frames[whole.frames.split == "val"]
    assert list(alone.frames.sha256) == list(val.sha256)
    assert set(alone.objects.object_id) == set(whole.objects[whole.objects.split == "val"].object_id)
