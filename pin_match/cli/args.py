"""Arguments several commands share, defined once: a matcher's config (--cfg, --weights), workers, quiet."""

from __future__ import annotations

import argparse

from pin_match.contract.registry import parse_overrides, with_weights


def add_matcher_config(s: argparse.ArgumentParser, whose: str = "the matcher's") -> None:
    """--cfg KEY=VALUE (repeatable) and --weights PATH; read them back with ``matcher_overrides``."""
    s.add_argument("--cfg", action="append", metavar="KEY=VALUE", help=f"{whose} config override (repeatable)")
    s.add_argument("--weights", help=f"local weights file or folder ({whose} weights=)")


def matcher_overrides(a: argparse.Namespace) -> dict:
    """The config overrides of ``add_matcher_config``: --cfg pairs, with --weights on top."""
    return with_weights(parse_overrides(a.cfg), a.weights)


def add_run_options(s: argparse.ArgumentParser, workers_help: str) -> None:
    s.add_argument("--workers", type=int, help=workers_help)
    s.add_argument("--quiet", action="store_true", help="no progress bars")
