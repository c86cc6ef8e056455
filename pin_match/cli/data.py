"""The data half of the CLI: ``pin-match data list | build | prepare``, over the catalogue of sources.

Every source is reached the same way (``pin_match.data.sources``): ``build SOURCE OUT`` writes its
frame-set, ``prepare SOURCE INPUT... --out SRC`` writes the source folder of a source whose photos
are downloaded, which ``build SOURCE OUT --src SRC`` then reads.
"""

from __future__ import annotations

import argparse
import textwrap
from pathlib import Path

DATA_HELP = """Frame-set sources, one catalogue: list them, prepare one from its download, build its frame-set.

  pin-match data list                                  every source: variants, what prepare reads, licence
  pin-match data build core50 OUT [--variant pasted]   a source's frame-set (shipped photos: offline)
  pin-match data build gso OUT                         the synthetic default set (as `pin-match synth OUT`)
  pin-match data prepare grocery GROCERY_REPO --out SRC
  pin-match data build grocery OUT --src SRC           a downloaded source: prepare once, then build
  pin-match data cohort FRAMESET OUT                   its objects' views as a cohort for cohort-norm
"""


def _cmd_list(a: argparse.Namespace) -> None:
    from pin_match.data.sources import get, names

    for name in names():
        s = get(name)
        prepare = f"prepare {' '.join(s.prepare_inputs)}" if s.prepare_inputs else "nothing to prepare"
        print(f"{name:10s} variants {', '.join(s.variants)}; {prepare}; --src {s.src}")
        if a.verbose:
            for text in (s.summary, f"licence: {s.licence}"):
                print(textwrap.fill(text, 100, initial_indent=" " * 11, subsequent_indent=" " * 11))


def _cmd_build(a: argparse.Namespace) -> None:
    from pin_match.data.sources import get

    print(f"wrote {get(a.source).build(a.out, a.variant, a.seed, src=a.src, overwrite=a.overwrite)}")


def _cmd_prepare(a: argparse.Namespace) -> None:
    from pin_match.data.sources import get

    print(f"wrote {get(a.source).prepare(a.inputs, a.out, overwrite=a.overwrite)}")


def _cmd_cohort(a: argparse.Namespace) -> None:
    from pin_match.data.cohort import write_cohort
    from pin_match.data.frameset import FrameSet

    print(f"wrote {write_cohort(FrameSet.load(a.frameset), a.out, views=a.views, overwrite=a.overwrite)}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    d = sub.add_parser("data", help="list, prepare and build frame-sets from the catalogue of data sources",
                       description=DATA_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    group = d.add_subparsers(dest="data_command", required=True, metavar="{list,build,prepare,cohort}",
                             help="what to do with the catalogue")

    s = group.add_parser("list", help="the sources: variants, what prepare reads, whether --src is needed")
    s.add_argument("-v", "--verbose", action="store_true", help="also what each source holds and its licence")
    s.set_defaults(func=_cmd_list)

    s = group.add_parser("build", help="write a source's frame-set")
    s.add_argument("source", help="a name from `pin-match data list`")
    s.add_argument("out", type=Path, help="frame-set folder to create")
    s.add_argument("--variant", help="the source's variant (default: its first, see `pin-match data list`)")
    s.add_argument("--seed", type=int, default=0, help="seed of every random choice (default 0); same seed, "
                                                       "same bytes")
    s.add_argument("--src", type=Path, help="source folder written by `pin-match data prepare` (core50, gso: "
                                            "default the one shipped with pin_match)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing frame-set at OUT")
    s.set_defaults(func=_cmd_build)

    s = group.add_parser("prepare", help="write a source folder from a source's download (a git checkout)")
    s.add_argument("source", help="a name from `pin-match data list`")
    s.add_argument("inputs", nargs="+", type=Path, metavar="INPUT",
                   help="what the source reads, in the order `pin-match data list` shows")
    s.add_argument("--out", type=Path, required=True, help="source folder to create")
    s.add_argument("--overwrite", action="store_true", help="replace an existing source folder at --out")
    s.set_defaults(func=_cmd_prepare)

    s = group.add_parser("cohort", help="a cohort folder for cohort-norm (--weights): a frame-set's objects' "
                                        "reference views on grey, with their sources in NOTICE.md")
    s.add_argument("frameset", type=Path, help="a frame-set whose objects differ from those of the houses scored")
    s.add_argument("out", type=Path, help="cohort folder to create")
    s.add_argument("--views", type=int, default=1, help="reference views per object (default 1)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing folder at OUT")
    s.set_defaults(func=_cmd_cohort)
