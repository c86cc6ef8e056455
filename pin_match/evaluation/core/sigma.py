"""Which sigma a number was computed at, and where that sigma came from.

Every command that thresholds (``report``, ``bench``, ``demo``) goes through ``resolve_sigma``
and carries the returned ``SigmaChoice`` into what it prints and writes, so no table or
caption can claim "tuned on train" for a sigma that was not. Thresholds files are read
here too: a tuned file (``pin-match tune``) or a table of several (``paper_thresholds.json``, package data).
A file records the stop policy its sigma was tuned for (none: PIN's rule); read for another
policy it is refused (``PolicyMismatchError``): its sigma is not that policy's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pin_match import atomic
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.stop import FIRST_MATCH, PolicyError, StopPolicy

# the paper's sigmas ship inside the package (package data), so ``--thresholds paper`` works from any install
PAPER_THRESHOLDS = Path(__file__).resolve().with_name("paper_thresholds.json")


class SigmaError(PinMatchError, ValueError):
    """No sigma can be given to a matcher from what was asked for."""


class PolicyMismatchError(SigmaError):
    """A thresholds file tuned for one stop policy, read for another."""


@dataclass(frozen=True)
class SigmaChoice:
    """A threshold and its provenance: ``source`` is short (a table cell), ``detail`` says it in full."""

    value: float
    source: str
    detail: str

    def as_dict(self) -> dict:
        return dict(sigma=self.value, sigma_source=self.source, sigma_detail=self.detail)


def way_out(matcher_id: str, split: str, available: list[str]) -> str:
    """The one message for a missing tuning split, with the three ways on."""
    others = [s for s in available if s != split]
    tune_hint = f"tune on a split it has (--split {others[0]}, an optimistic sigma if you then report that split)" \
        if others else "tune on a frame-set that has one"
    return (f"score table of {matcher_id} has no frames of split {split!r} (it has {available}): {tune_hint}, "
            "pass --threshold SIGMA, or --thresholds paper for the paper's sigma")


def resolve_sigma(matcher_id: str, default_sigma: float | None, sigma: float | None = None,
                  thresholds: str | Path | None = None, policy: StopPolicy = FIRST_MATCH) -> SigmaChoice:
    """Explicit sigma, else a thresholds file (``"paper"`` = the paper's) tuned for ``policy``, else the matcher's
    default."""
    if sigma is not None and thresholds is not None:
        raise SigmaError("give either a threshold or a thresholds file, not both")
    if sigma is not None:
        if not np.isfinite(sigma):
            raise SigmaError(f"threshold {sigma!r} is not a finite number")
        return SigmaChoice(float(sigma), "given", "given on the command line / as an argument")
    if thresholds is not None:
        return load_threshold(thresholds, matcher_id, policy)
    if default_sigma is not None:
        return SigmaChoice(float(default_sigma), "matcher default", f"{matcher_id.split('@')[0]}'s default sigma")
    raise SigmaError(f"{matcher_id} has no default sigma: pass --threshold SIGMA or --thresholds FILE")


def thresholds_path(thresholds: str | Path) -> Path:
    if str(thresholds) == "paper":
        if not PAPER_THRESHOLDS.exists():
            raise SigmaError(f"the paper's thresholds ({PAPER_THRESHOLDS}) are missing from this install of "
                             "pin_match: reinstall it")
        return PAPER_THRESHOLDS
    return Path(thresholds)


def load_threshold(thresholds: str | Path, matcher_name: str, policy: StopPolicy = FIRST_MATCH) -> SigmaChoice:
    """Sigma for a matcher under stop policy ``policy`` from a tuned file (``{"matcher", "sigma", ...}``) or a table of
    several; a file tuned for another policy is refused (``PolicyMismatchError``).

    The table form is ``paper_thresholds.json``, package data: ``{"source": ..., "thresholds": {name: {"sigma": x}}}``
    (an optional ``label`` is the sigma's source in a table cell, as the demo's shipped sigmas say where they come
    from).
    ``matcher_name`` may be a registry name or a full id (``name@hash``).
    """
    path = thresholds_path(thresholds)
    if not path.exists():
        raise SigmaError(f"no thresholds file {path}: run `pin-match tune` first (it writes it), pass --threshold "
                         "SIGMA, or --thresholds paper")
    data = atomic.read_json(path, SigmaError, "thresholds file")
    _check_policy(data, path, policy)
    names = {matcher_name, matcher_name.split("@")[0]}
    if isinstance(data, dict) and "sigma" in data:
        if data.get("matcher") not in names and data.get("matcher_id") not in names:
            raise SigmaError(f"{path} holds the threshold of {data.get('matcher')!r}, not {matcher_name!r}")
        _sigma(data["sigma"], path, matcher_name)
        return tuned_choice(data, f"read from {path}")
    if isinstance(data, dict) and isinstance(data.get("thresholds"), dict):
        table = data["thresholds"]
        covered = sorted(k for k, v in table.items() if _entry(v) is not None)
        for name in (matcher_name, matcher_name.split("@")[0]):
            if name in table:
                if _entry(table[name]) is None:
                    raise SigmaError(f"{path} gives no sigma for {name!r} ({_note(table[name])}); it gives one for "
                                     f"{', '.join(covered)}. Tune {name} or pass --threshold SIGMA")
                value = _sigma(_entry(table[name]), path, name)
                label = "paper" if path == PAPER_THRESHOLDS else str(data.get("label", "table"))
                return SigmaChoice(value, label, f"{name}'s entry in {path}: {data.get('source', 'no source given')}")
        raise SigmaError(f"{path} has no threshold for {matcher_name!r}; it covers only {', '.join(covered)}. "
                         f"Tune {matcher_name.split('@')[0]} (pin-match tune) or pass --threshold SIGMA")
    raise SigmaError(f"{path} is neither a tuned thresholds file nor a {{'thresholds': {{...}}}} table")


def _check_policy(data: object, path: Path, policy: StopPolicy) -> None:
    """A sigma tuned for one stop policy is not another's: a file that records another (none: PIN's rule) is refused."""
    text = data.get("policy", str(FIRST_MATCH)) if isinstance(data, dict) else str(FIRST_MATCH)
    try:
        tuned_for = StopPolicy.parse(str(text))
    except PolicyError as exc:
        raise SigmaError(f"{path}: {exc}") from None
    if tuned_for != policy:
        raise PolicyMismatchError(f"{path} was tuned for stop policy {tuned_for}, not {policy}: tune for it "
                                  f"(pin-match tune --policy '{policy}') or give the sigma")


def tuned_choice(result: dict, where: str) -> SigmaChoice:
    """The choice a tuning result (``tuning.tune``'s, or its file's content) makes; ``where`` says where it is."""
    how = f"{result.get('objective')} on {result.get('split')}" if result.get("objective") else "tuned"
    if result.get("policy") not in (None, "1-of-1"):
        how += f" for {result['policy']}"
    return SigmaChoice(float(result["sigma"]), f"tuned: {how}", f"tuned ({how}), {where}")


def _entry(value: object) -> object:
    return value.get("sigma") if isinstance(value, dict) else value


def _note(value: object) -> str:
    return str(value.get("note", "no value")) if isinstance(value, dict) else "no value"


def _sigma(value: object, path: Path, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise SigmaError(f"{path}: threshold of {name!r} is {value!r}, not a number")
    return float(value)
