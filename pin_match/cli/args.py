"""Arguments several commands share, each defined once: a matcher's config, run options, a dataclass's fields.

Every ``add_*`` has its reader (``matcher_overrides``, ``bench_overrides``, ``run_options``,
``engine_run``, ``dataclass_values``), so a command never spells a shared flag or its default itself.
"""

from __future__ import annotations

import argparse
import dataclasses
import typing
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

from pin_match.contract.matcher import ConfigError
from pin_match.contract.registry import parse_overrides, with_weights
from pin_match.errors import PinMatchError
from pin_match.scoring.options import DEFAULT_RUN, RunOptions


def add_matcher_config(s: argparse.ArgumentParser, whose: str = "the matcher's") -> None:
    """--cfg KEY=VALUE (repeatable) and --weights PATH; read them back with ``matcher_overrides``."""
    s.add_argument("--cfg", action="append", metavar="KEY=VALUE", help=f"{whose} config override (repeatable)")
    s.add_argument("--weights", help=f"local weights file or folder ({whose} weights=)")


def matcher_overrides(a: argparse.Namespace) -> dict:
    """The config overrides of ``add_matcher_config``: --cfg pairs, with --weights on top."""
    return with_weights(parse_overrides(a.cfg), a.weights)


def add_bench_config(s: argparse.ArgumentParser) -> None:
    """--cfg MATCHER:KEY=VALUE (repeatable): several matchers run side by side, so each pair names its matcher."""
    s.add_argument("--cfg", action="append", metavar="MATCHER:KEY=VALUE",
                   help="config override of one of the --matcher matchers, e.g. effnet:img_size=224 or "
                        "effnet:weights=PATH (repeatable)")


def bench_overrides(pairs: Sequence[str] | None, matchers: Sequence[str], verb: str = "benched") -> dict[str, dict]:
    """Each of ``matchers`` with its overrides from ``add_bench_config`` (the name ends at the first ':' before any
    '='); overrides for a matcher not among them are refused before anything runs."""
    grouped: dict[str, list[str]] = {}
    for pair in pairs or []:
        name, sep, rest = pair.partition(":")
        if not sep or not name or "=" in name:
            raise ConfigError(f"--cfg {pair!r}: expected MATCHER:KEY=VALUE (bench runs several matchers), "
                              "e.g. effnet:img_size=224")
        grouped.setdefault(name.strip(), []).append(rest)
    stray = sorted(set(grouped) - set(matchers))
    if stray:
        raise ConfigError(f"config overrides for {', '.join(stray)}, which is not among the {verb} matchers "
                          f"({', '.join(matchers)}): add it with --matcher or fix the name before ':'")
    return {name: parse_overrides(grouped.get(name, [])) for name in matchers}


def add_run_options(s: argparse.ArgumentParser, *, workers: str | None, batch_size: bool = True) -> None:
    """--quiet, and --batch-size and --workers (help: ``workers``) where the command has them: a ``RunOptions``."""
    if batch_size:
        s.add_argument("--batch-size", type=int, default=DEFAULT_RUN.batch_size,
                       help=f"frames per matcher call (default {DEFAULT_RUN.batch_size})")
    if workers is not None:
        s.add_argument("--workers", type=int, help=workers)
    s.add_argument("--quiet", action="store_true", help="no progress bars")


def run_options(a: argparse.Namespace) -> RunOptions:
    """The ``RunOptions`` of ``add_run_options``; an option the command lacks keeps its default."""
    given = {name: getattr(a, name) for name in ("batch_size", "workers") if hasattr(a, name)}
    return RunOptions(**given, progress=not a.quiet)


def add_scheduler(s: argparse.ArgumentParser) -> None:
    """--scheduler and --scheduler-timeout, for a command whose per-frame work runs through the scoring engine."""
    s.add_argument("--scheduler", metavar="local|ADDRESS",
                   help="run the per-frame work on Dask distributed: 'local' starts --workers worker processes "
                        "here; else a scheduler address (tcp://host:8786) or scheduler JSON file; same cache and "
                        "tables")
    s.add_argument("--scheduler-timeout", type=float, default=30.0, metavar="SECONDS",
                   help="give up on an unreachable --scheduler after this long (default 30)")


@contextmanager
def engine_run(a: argparse.Namespace) -> Iterator[RunOptions]:
    """``run_options(a)``, with a client of ``--scheduler``'s cluster when one is given (closed after the block)."""
    run = run_options(a)
    if not getattr(a, "scheduler", None):
        yield run
        return
    from pin_match.scoring.cluster import connect

    with connect(a.scheduler, workers=run.workers, timeout=a.scheduler_timeout) as client:
        yield replace(run, client=client)


def add_dataclass_flags(s: argparse.ArgumentParser, cls: type, choices: dict[str, Sequence[str]] | None = None) -> None:
    """One --flag per field of a dataclass (its ``metadata["help"]``, typed and defaulted by the field itself).

    The flags cannot drift from the class: a new field is a new flag, a changed default shows in
    the help. ``choices`` restricts fields whose valid values live in another layer.
    """
    defaults = cls()
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        default = getattr(defaults, f.name)
        s.add_argument(f"--{f.name.replace('_', '-')}", type=hints[f.name], default=default,
                       choices=(choices or {}).get(f.name), help=f"{f.metadata['help']} (default {default})")


def dataclass_values(a: argparse.Namespace, cls: type) -> Any:
    """The dataclass built from the flags of ``add_dataclass_flags``."""
    return cls(**{f.name: getattr(a, f.name) for f in dataclasses.fields(cls)})


def policy_argument(s: argparse.ArgumentParser, what: str) -> None:
    """``--policy``: one stop policy, ``what`` saying what it is for."""
    s.add_argument("--policy", metavar="POLICY",
                   help=f"{what}: K-of-N (found when K of the last N frames are above sigma), house:topT+MARGIN "
                        "(above sigma and the mean of the T highest earlier scores of the episode plus MARGIN) or "
                        "look:W[+CLEAR] (after the first firing look W more frames, then commit to the best "
                        "candidate; look:rest is the whole walk, an upper bound) or approach:D[+SIGMA2] (walk up to "
                        "a candidate, commit where a view within D m reaches SIGMA2, default sigma; tune finds SIGMA2 "
                        "when it is not given); default 1-of-1, PIN's rule; docs/metrics.md, 'Stop policies'")


def policy_of(a: argparse.Namespace):
    """The stop policy of ``--policy`` (PIN's first match without one)."""
    from pin_match.evaluation.core.stop import FIRST_MATCH, StopPolicy

    return FIRST_MATCH if a.policy is None else StopPolicy.parse(a.policy)


class UsageError(PinMatchError, ValueError):
    """Arguments that argparse cannot check alone."""
