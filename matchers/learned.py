"""``learned``: the prototype matcher of a patch backbone, with a head trained by ``pin-match train`` on top.

``--weights heads/NAME`` names the folder ``pin-match train`` wrote. Its config.json says
which backbone matcher (name and config) the head was trained on; that matcher's
backbone is built lazily and wrapped so every patch token goes through the head, and the
usual prototype math (mask-weighted prototypes per reference view, cosine, max) runs
unchanged. The matcher id carries a content hash of the head folder, so retraining into
the same folder never reuses old score caches; the backbone matcher's id is checked
against the one recorded at training time, so a head is never run on other features.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from pin_match.contract import (
    CropConfig,
    MatcherConfig,
    PinMatchError,
    WeightsError,
    WeightsSpec,
    misfit,
    register_matcher,
    weights_field,
)
from pin_match.matchers.common.patch import ReferencePrototypeMatcher, patch_matcher


@dataclass
class LearnedConfig(CropConfig):
    weights: str | None = weights_field()


@dataclass(frozen=True)
class HeadWeightsSpec(WeightsSpec):
    """A head has no default source: it exists only as a folder the user trained."""

    @property
    def source(self) -> str:
        return "a head folder from pin-match train"

    def available(self, override: str | None = None) -> bool:
        return override is not None and Path(override).expanduser().is_dir()


@register_matcher("learned")
class LearnedMatcher(ReferencePrototypeMatcher):
    """A trained residual projection head on a frozen patch backbone (docs/training.md)."""

    Config = LearnedConfig
    weights_spec = HeadWeightsSpec(license="that of the backbone's weights (see the head's config.json)")
    default_sigma = 0.5
    paper = "pin_match: a projection head trained on the train split against same-category look-alikes"
    version = 1

    def __init__(self, cfg: MatcherConfig | None = None, **kwargs) -> None:
        super().__init__(cfg, **kwargs)
        if self.cfg.weights is not None and (Path(self.cfg.weights).expanduser() / "config.json").is_file():
            from pin_match.nn.head import read_head_config

            sigma = read_head_config(Path(self.cfg.weights).expanduser()).get("sigma")
            if sigma is not None:  # the sigma tuned at training time, on held-out train objects
                self.default_sigma = float(sigma)

    @property
    def backbone(self):
        """Built on first use; any failure to load the head or its backbone names the head folder."""
        if self._backbone is None:
            try:
                self._backbone = self._build_backbone()
            except PinMatchError:
                raise
            except (RuntimeError, ValueError, KeyError, OSError) as exc:
                raise misfit(f"matcher {self.display_name}", self.cfg.weights or "(none)", "its trained head",
                             exc) from exc
        return self._backbone

    def _build_backbone(self):
        from pin_match.nn.head import HeadBackbone, HeadError, load_head

        folder = self.weights_spec.local_path(self.cfg.weights)
        if folder is None:
            raise WeightsError(f"matcher {self.display_name} needs weights=heads/NAME, a folder written by "
                               f"pin-match train")
        try:
            head, config = load_head(folder)
        except HeadError as exc:
            raise WeightsError(f"matcher {self.display_name}: {exc}") from exc
        overrides = dict(config.get("backbone_cfg") or {})
        base = patch_matcher(config["backbone"], **overrides)
        if base.id != config.get("backbone_id"):
            raise WeightsError(f"matcher {self.display_name}: head {folder} was trained on "
                               f"{config.get('backbone_id')}, but {config['backbone']} with its recorded config is "
                               f"now {base.id} (other weights or version): retrain the head")
        if self.cfg.device != base.cfg.device:
            base = type(base)(dataclasses.replace(base.cfg, device=self.cfg.device))
        return HeadBackbone(base.backbone, head)  # the base returns CPU tokens; the small head runs there
