"""What the composite matchers (``ieve``, ``parts-cascade``, ``fusion``) share: parts built by name from nested configs.

A composite is made of registered matchers, its parts, each built by name from a config dict
of its own (``gate_cfg``, ``patch_cfg``, ... or a fusion file's ``config``): on the command
line ``--cfg patch_cfg.img_size=448`` sets one key of it. The part's id, which hashes its
whole config and weights, enters the composite's id (``Matcher.config_hash``), so the dict
itself stays out of the composite's hash: the same part spelled ``"448"`` or ``448`` is one id.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import field
from typing import Any

from pin_match.contract import (
    ConfigError,
    Matcher,
    MatcherConfig,
    Modality,
    PinMatchError,
    Target,
    WeightsError,
    create_matcher,
)


def part_cfg_field(role: str) -> Any:
    """The config dict of the part ``role``: keys of that matcher's config (its id enters the composite's)."""
    return field(default_factory=dict, metadata={
        "hash": False, "help": f"config of the {role} part, e.g. --cfg {role}_cfg.weights=PATH"})


class CompositeMatcher(Matcher):
    """A matcher built from registered matchers; ``add_part`` in the constructor, ``_match_batch`` to combine.

    ``_match_batch`` receives the batch as ``Frames``: a part run on those frames is asked of it
    (``frames.results(part)``), so it runs once however many matchers of a run use it."""

    def __init__(self, cfg: MatcherConfig | None = None) -> None:
        super().__init__(cfg)
        self._parts: dict[str, Matcher] = {}

    def add_part(self, role: str, name: str, overrides: Mapping[str, Any],
                 defaults: Mapping[str, Any] | None = None) -> Matcher:
        """The registered matcher ``name`` configured by ``overrides`` on top of this composite's ``defaults`` for
        it, on this composite's device unless they say otherwise."""
        if name == self.name:
            raise ConfigError(f"matcher {self.display_name} cannot use itself as a part")
        if not isinstance(overrides, Mapping):
            raise ConfigError(f"matcher {self.display_name}: the {role} part's config must be a dict of config keys, "
                              f"got {overrides!r}")
        try:
            part = create_matcher(name, **{"device": self.cfg.device, **(defaults or {}), **overrides})
        except ConfigError as exc:
            raise ConfigError(f"matcher {self.display_name}, {role} part: {exc}") from exc
        self._parts[role] = part
        return part

    def parts(self) -> dict[str, Matcher]:
        return dict(self._parts)

    def share_parts(self, peers: Sequence[Matcher]) -> None:
        """A part configured as one of the run's other matchers (same class, id and device) becomes that matcher: its
        ``prepare`` (the reference encodings) then runs once for both, as its results on a batch already do."""
        for role, part in list(self._parts.items()):
            twin = next((p for p in peers if p is not self and type(p) is type(part) and p.id == part.id
                         and p.cfg.device == part.cfg.device), None)
            if twin is None:
                continue
            self._parts[role] = twin
            for name, value in list(vars(self).items()):  # the attribute a subclass keeps its part under
                if value is part:
                    setattr(self, name, twin)

    def require_visual(self, where: str = "", error: type[PinMatchError] = ConfigError) -> None:
        """Refuse a part that reads text or the label: a visual composite must see reference views only."""
        for role, part in self._parts.items():
            if part.modality is not Modality.VISUAL:
                raise error(f"{where or 'matcher ' + self.display_name}: {role} part {part.display_name!r} is of the "
                            f"{part.modality.value} modality; {self.display_name} takes visual parts only")

    def weights_hint(self, role: str) -> str:
        """How the user points the part ``role`` at other weights, as the error of a missing checkpoint says."""
        return f"set {role}_cfg.weights="

    def roles_to_prepare(self) -> tuple[str, ...]:
        """The parts ``prepare`` prepares for a target: all of them, unless a composite uses one only for its
        network (``verify``'s zoom) or leaves one off by config (its keypoints when that signal is not used)."""
        return tuple(self._parts)

    def _prepare(self, target: Target) -> None:
        # the full target: a category-modality part gets the label, any other part strips it itself
        for role in self.roles_to_prepare():
            part = self._parts[role]
            try:
                part.prepare(target)
            except WeightsError as exc:
                raise WeightsError(f"matcher {self.display_name}, {role} part {part.display_name!r} "
                                   f"({self.weights_hint(role)}): {exc}") from exc
