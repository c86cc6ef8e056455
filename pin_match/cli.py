"""pin-match: score, tune and report PIN matchers on frame-sets, offline.

A thin command line over the same functions notebooks call. Every failure a user can
cause (bad frame-set, unknown matcher or key, unwritable output) is a ``PinMatchError``
and ends in one line on stderr naming the culprit, exit code 2. Any other exception is a
bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pin_match.errors import PinMatchError
from pin_match.registry import parse_overrides


def _cmd_synth(a: argparse.Namespace) -> None:
    from pin_match.synth import generate

    kwargs = {k: v for k, v in dict(seed=a.seed, episodes=a.episodes, objects_per_category=a.objects_per_category,
                                    frames_per_episode=a.frames_per_episode, workers=a.workers).items()
              if v is not None}
    fs = generate(a.out, overwrite=a.overwrite, **kwargs)
    print(f"wrote {fs}")


def _cmd_import(a: argparse.Namespace) -> None:
    from pin_match.importer import import_recording

    fs = import_recording(a.recording, a.objects, a.out, split=a.split, overwrite=a.overwrite)
    print(f"wrote {fs}")


def _cmd_score(a: argparse.Namespace) -> None:
    import pandas as pd

    from pin_match.scoring import read_meta, score_to_file

    path = score_to_file(a.frameset, a.matcher, overrides=parse_overrides(a.cfg), weights=a.weights, split=a.split,
                         out=a.out, batch_size=a.batch_size, shard=a.shard, workers=a.workers, progress=not a.quiet)
    s = pd.read_parquet(path, columns=["score"]).score
    summary = f"score min {s.min():.4g} / mean {s.mean():.4g} / max {s.max():.4g}" if len(s) else "no frames"
    print(f"{read_meta(path)['matcher_id']}: {len(s)} frames, {summary} -> {path}")


def _cmd_merge(a: argparse.Namespace) -> None:
    from pin_match.scoring import merge

    table = merge(a.parts, a.out)
    print(f"merged {len(a.parts)} parts, {len(table.frames)} frames -> {a.out}")


def _cmd_list(a: argparse.Namespace) -> None:
    from pin_match.catalog import matcher_catalog

    cat = matcher_catalog(a.pattern)
    print(cat.to_string(index=False) if len(cat) else f"no matcher matches {a.pattern!r}")


def _add_eval_commands(sub: argparse._SubParsersAction) -> None:
    from pin_match import cli_eval

    cli_eval.add_commands(sub)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pin-match", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("synth", help="generate a synthetic PIN-like frame-set")
    s.add_argument("out", type=Path)
    s.add_argument("--seed", type=int)
    s.add_argument("--episodes", type=int)
    s.add_argument("--objects-per-category", type=int)
    s.add_argument("--frames-per-episode", type=int)
    s.add_argument("--workers", type=int)
    s.add_argument("--overwrite", action="store_true")
    s.set_defaults(func=_cmd_synth)

    s = sub.add_parser("import", help="build a frame-set from a PIN recording folder")
    s.add_argument("recording", type=Path)
    s.add_argument("--objects", type=Path, required=True, help="PInNED objects folder")
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--split", default="val")
    s.add_argument("--overwrite", action="store_true")
    s.set_defaults(func=_cmd_import)

    s = sub.add_parser("score", help="score a frame-set with a matcher (cached, resumable)")
    s.add_argument("frameset", type=Path)
    s.add_argument("--matcher", required=True)
    s.add_argument("--cfg", action="append", metavar="KEY=VALUE", help="config override (repeatable)")
    s.add_argument("--weights", help="local weights file or folder")
    s.add_argument("--split")
    s.add_argument("--out", type=Path, default=Path("pin_match_runs/scores"))
    s.add_argument("--batch-size", type=int, default=8)
    s.add_argument("--shard", help="i/n: score a deterministic part")
    s.add_argument("--workers", type=int)
    s.add_argument("--quiet", action="store_true")
    s.set_defaults(func=_cmd_score)

    s = sub.add_parser("merge", help="join shard score tables")
    s.add_argument("parts", nargs="+", type=Path)
    s.add_argument("--out", type=Path, required=True)
    s.set_defaults(func=_cmd_merge)

    s = sub.add_parser("list", help="registered matchers")
    s.add_argument("pattern", nargs="?", default="*")
    s.set_defaults(func=_cmd_list)

    _add_eval_commands(sub)
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
