"""``pin-match list``: one short row per registered matcher, the detail of one on request.

Each matcher is built with its default config (which loads nothing), so what is listed is
what the instance really is: its modality may depend on the config, and a composite's
weights are those of its parts. A row says only whether the weights are on this machine,
so it fits a terminal; where they come from and under which licence (long texts) are in
the detail, shown by ``--verbose`` or by naming one matcher exactly.
"""

from __future__ import annotations

import argparse
import textwrap
from dataclasses import dataclass

from pin_match.contract.matcher import Matcher
from pin_match.contract.registry import create_matcher, get_matcher_class, list_matchers
from pin_match.errors import PinMatchError

WIDTH = 100  # the columns every row and detail line fits in
LABEL = 11  # the width of a detail line's label column
# what the weights column can say, worst first: a composite says the worst of its parts
MISSING, AVAILABLE, NONE, UNLOADABLE = "missing", "available", "none", "cannot load"


@dataclass(frozen=True)
class Entry:
    """What ``pin-match list`` knows of one matcher."""

    name: str
    modality: str
    default_sigma: float | None
    weights: str  # MISSING, AVAILABLE, NONE or UNLOADABLE
    sources: tuple[str, ...]  # where each weight file comes from (a composite's by part), or why it cannot load
    licences: tuple[str, ...]
    paper: str = ""
    score_scale: str = ""

    @property
    def scale(self) -> str:
        """The scale's short name (``Matcher.score_scale`` before its colon)."""
        return self.score_scale.split(":")[0] or "?"


def weights_status(matcher: Matcher) -> tuple[str, tuple[str, ...], tuple[str, ...]]:
    """(available, missing or none; each source with its state; each licence): its own file, then its parts' by role."""
    states, sources, licences = [NONE], [], []
    spec = matcher.weights_spec
    if spec is not None:
        local = spec.available()
        states.append(AVAILABLE if local else MISSING)
        sources.append(f"{spec.source} ({'available' if local else 'not local, pass weights='})")
        licences += [spec.license] if spec.license else []
    for role, part in matcher.parts().items():
        state, part_sources, part_licences = weights_status(part)
        states.append(state)
        sources += [f"{role} {part.display_name}: {source}" for source in part_sources]
        licences += [f"{role}: {licence}" for licence in part_licences]
    return min(states, key=[MISSING, AVAILABLE, NONE].index), tuple(sources), tuple(licences)


def entry(name: str) -> Entry:
    try:
        matcher = create_matcher(name)
    except (ImportError, PinMatchError) as exc:  # a plug-in that cannot load is listed, not fatal
        return Entry(name, "?", None, UNLOADABLE, (str(exc),), ())
    weights, sources, licences = weights_status(matcher)
    return Entry(name, matcher.modality.value, matcher.default_sigma, weights, sources, licences, matcher.paper,
                 matcher.score_scale)


def rows(entries: list[Entry]) -> str:
    """A header and one row per matcher: name, modality, default sigma, the score's scale, whether the weights are
    local."""
    width = max([len("name"), *(len(e.name) for e in entries)])
    lines = [f"{'name':<{width}}  {'modality':<8}  {'sigma':>6}  {'scale':<17}  weights", "-" * (width + 55)]
    for e in entries:
        sigma = "?" if e.default_sigma is None else f"{e.default_sigma:.4g}"
        lines.append(f"{e.name:<{width}}  {e.modality:<8}  {sigma:>6}  {e.scale:<17}  {e.weights}")
    return "\n".join(lines)


def detail(e: Entry) -> str:
    """Everything listed of one matcher, each long text wrapped under its label."""
    fields = [("modality", [e.modality]), ("sigma", [f"{e.default_sigma}"]), ("scale", [e.score_scale]),
              ("paper", [e.paper]),
              ("weights", [e.weights]), ("sources", list(e.sources)), ("licences", list(e.licences))]
    lines = [e.name]
    for label, texts in fields:
        for i, text in enumerate(t for t in texts if t):
            head = f"  {label if i == 0 else '':<{LABEL}}"
            lines.append(textwrap.fill(text, WIDTH, initial_indent=head, subsequent_indent=" " * len(head),
                                       break_on_hyphens=False))
    return "\n".join(lines)


def _cmd_list(a: argparse.Namespace) -> None:
    if not any(c in a.pattern for c in "*?["):  # one name: its detail, or the registry's did-you-mean
        get_matcher_class(a.pattern)
        print(detail(entry(a.pattern)))
        return
    entries = [entry(name) for name in list_matchers(a.pattern)]
    if not entries:
        print(f"no matcher matches {a.pattern!r}")
    elif a.verbose:
        print("\n\n".join(detail(e) for e in entries))
    else:
        print(rows(entries))


def add_commands(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("list", help="registered matchers: name, modality, default sigma, the score's scale (raw or "
                                    "normalised), whether the weights are local; a name or --verbose for sources "
                                    "and licences")
    s.add_argument("pattern", nargs="?", default="*",
                   help="a shell-style name pattern (default: all), or one name for its detail")
    s.add_argument("--verbose", "-v", action="store_true", help="the detail of every listed matcher")
    s.set_defaults(func=_cmd_list)
