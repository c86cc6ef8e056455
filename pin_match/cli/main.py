"""pin-match: score, tune and report PIN matchers on frame-sets, offline.

A thin command line over the same functions notebooks call. Every failure a user can
cause (bad frame-set, unknown matcher or key, unwritable output) is a ``PinMatchError``
and ends in one line on stderr naming the culprit, exit code 2. Any other exception is a
bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from pin_match import outputs
from pin_match.cli import catalog, data, evaluation, fitting, pages, policies, training
from pin_match.cli.args import (
    UsageError,
    add_matcher_config,
    add_run_options,
    add_scheduler,
    engine_run,
    matcher_overrides,
    run_options,
)
from pin_match.data.synth import SynthSize
from pin_match.data.synth.size import PRESETS, WALKS
from pin_match.errors import PinMatchError

IMPORT_HELP = """Build a frame-set from a PIN recording and the PInNED objects folder.

  RECORDING/episodes.json[.gz]                {"episodes": [{episode_id, goals: [{object_id, object_category}],
                                                distractors: [{object_id, object_category}, ...],
                                                scene_id (optional), split (optional: train | val)}]}
  RECORDING/<episode_id>/rgb/<step>.png|.jpg  RGB frames named by their integer step
  RECORDING/<episode_id>/semantic/<step>.npy  PIN labels: 100000 target, 100001 same-category, 100002 other
  RECORDING/<episode_id>/depth/<step>.npy     depth in metres (optional)
  OBJECTS/objects_images/<id>/<id>_0.png      frontal view (RGBA), <id>_1.png back, <id>_2.png top,
                                              for the goal and every distractor of every episode
  OBJECTS/objects_descriptions.json           {<id>: [3 descriptions]} for the same objects

An episode without a split key gets --split; each object takes the split of the episodes
that use it (an object used by train and val episodes is an error).
"""


def _cmd_synth(a: argparse.Namespace) -> None:
    from pin_match.data.synth import generate

    given = dict(seed=a.seed, episodes=a.episodes, frames_per_episode=a.frames_per_episode,
                 objects_per_family=a.objects_per_family, walk=a.walk, rooms=a.rooms)
    size = replace(PRESETS[a.preset], **{k: v for k, v in given.items() if v is not None})
    fs = generate(a.out, size, scans=a.scans, workers=a.workers, overwrite=a.overwrite,
                  progress=run_options(a).progress)
    print(f"wrote {fs}")


def _cmd_import(a: argparse.Namespace) -> None:
    from pin_match.data.importer import import_recording

    fs = import_recording(a.recording, a.objects, a.out, split=a.split, image_format=a.image_format,
                          overwrite=a.overwrite)
    print(f"wrote {fs}")


def _cmd_score(a: argparse.Namespace) -> None:
    import pandas as pd

    from pin_match.contract.registry import create_matcher
    from pin_match.scoring import Job, read_meta, run_jobs

    names = list(dict.fromkeys(a.matcher))
    if len(names) < len(a.matcher):
        raise UsageError(f"--matcher {' '.join(a.matcher)}: a matcher is named twice")
    overrides = matcher_overrides(a)
    if overrides and len(names) > 1:
        raise UsageError(f"--cfg/--weights with {len(names)} matchers: they configure one matcher; score the "
                         "configured one alone, or use `pin-match bench` (--cfg MATCHER:KEY=VALUE)")
    jobs = [Job(create_matcher(name, **overrides)) for name in names]  # every name checked before anything runs
    with engine_run(a) as run:
        paths = run_jobs(a.frameset, jobs, split=a.split, out=a.out, shard=a.shard, run=run)
    for path in paths:  # one pass over the frames for every matcher: each frame decoded once, shared parts once
        s = pd.read_parquet(path, columns=["score"]).score
        summary = f"score min {s.min():.4g} / mean {s.mean():.4g} / max {s.max():.4g}" if len(s) else "no frames"
        print(f"{read_meta(path)['matcher_id']}: {len(s)} frames, {summary} -> {path}")


def _cmd_merge(a: argparse.Namespace) -> None:
    from pin_match.scoring.cache import merge

    table = merge(a.parts, a.out)
    print(f"merged {len(a.parts)} parts, {len(table.frames)} frames -> {a.out}")


def _add_synth(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("synth", help="generate a synthetic PIN-like frame-set of chosen sizes (docs/synthetic.md; "
                                     "every other source: `pin-match data`)")
    s.add_argument("out", type=Path, help="frame-set folder to create")
    default = SynthSize()
    s.add_argument("--preset", choices=sorted(PRESETS), default="default",
                   help="named sizes the options below override: 'default' the embedded default set (30 episodes), "
                        "'bench' 200 episodes (100 val: SR intervals of about +-10 points; docs/performance.md)")
    s.add_argument("--seed", type=int, help=f"generator seed (default {default.seed}); same seed and sizes, same bytes")
    s.add_argument("--episodes", type=int, help=f"episodes, half train and half val (default {default.episodes})")
    s.add_argument("--objects-per-family", type=int, help="at most this many instances of a look-alike family in "
                                                          f"each split (default {default.objects_per_family})")
    s.add_argument("--frames-per-episode", type=int, help="camera frames per episode: the tour's step budget (it ends "
                                                          "when it has seen every piece of furniture), or about the "
                                                          "seeking walk's length, longer where its run at "
                                                          f"the target needs it (default {default.frames_per_episode})")
    s.add_argument("--walk", choices=WALKS, help="'explore' (default): one exploration per house that does not know "
                                                 "the target, every episode of the house reads it; 'seek': each "
                                                 "episode's walk heads for its target and stops beside it (it knows "
                                                 "the answer: first-match studies only)")
    s.add_argument("--rooms", type=int, help=f"rooms per house, in a row joined by doors (default {default.rooms})")
    s.add_argument("--scans", type=Path, help="a scan folder from `pin-match data prepare gso` (default: the scans "
                                              "shipped with pin_match); its families.csv names the families")
    add_run_options(s, workers="rendering processes (default: all cores); output is the same", batch_size=False)
    s.add_argument("--overwrite", action="store_true", help="replace an existing frame-set at OUT")
    s.set_defaults(func=_cmd_synth)


def _add_import(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("import", help="build a frame-set from a PIN recording folder (layout: docs/frameset.md)",
                       description=IMPORT_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("recording", type=Path, help="recording folder: episodes.json[.gz] and one folder per episode")
    s.add_argument("--objects", type=Path, required=True,
                   help="PInNED objects folder: objects_images/<id>/<id>_0|1|2.png and objects_descriptions.json, "
                        "for the goal AND every distractor")
    s.add_argument("--out", type=Path, required=True, help="frame-set folder to create")
    s.add_argument("--split", default="val",
                   help="split of episodes without a 'split' key (default val); objects take their episodes' split")
    s.add_argument("--image-format", choices=("source", "png", "jpeg"), default="source",
                   help="how frames are stored: 'source' keeps each file's bytes (lossless, default), 'png' "
                        "re-encodes losslessly, 'jpeg' re-encodes at quality 95 (smaller, lossy)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing frame-set at --out")
    s.set_defaults(func=_cmd_import)


def _add_score_and_merge(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("score", help="score a frame-set with one matcher or several in one pass (cached, resumable)")
    s.add_argument("frameset", type=Path, help="frame-set folder (from `pin-match synth` or `pin-match import`)")
    s.add_argument("--matcher", required=True, action="append",
                   help="registered matcher name (`pin-match list`); repeat it to score several in one pass over the "
                        "frames (each frame decoded once, a part they share computed once), one table each")
    add_matcher_config(s)
    s.add_argument("--split", help="score only this split (default: every frame)")
    s.add_argument("--out", type=Path, default=outputs.SCORES,
                   help="score cache; the table goes to <out>/<matcher@hash>/<fingerprint>/ and its path is printed")
    s.add_argument("--shard", help="i/n: score a deterministic part (join the parts with `pin-match merge`)")
    add_run_options(s, workers="threads decoding and scoring frames (default up to 2); with --scheduler local, "
                               "worker processes")
    add_scheduler(s)
    s.set_defaults(func=_cmd_score)

    s = sub.add_parser("merge", help="join shard score tables")
    s.add_argument("parts", nargs="+", type=Path, help="shard tables of one matcher and frame-set")
    s.add_argument("--out", type=Path, required=True, help="merged table to write (parquet)")
    s.set_defaults(func=_cmd_merge)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pin-match", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    _add_synth(sub)
    _add_import(sub)
    _add_score_and_merge(sub)
    for group in (catalog, data, evaluation, policies, pages, training, fitting):
        group.add_commands(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except PinMatchError as exc:
        print(f"pin-match {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"pin-match {args.command}: interrupted; rerun the same command to resume", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
