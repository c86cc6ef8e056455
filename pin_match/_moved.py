"""Old module paths from before the layered layout, kept as aliases of the same module objects.

``import pin_match.registry`` still works and gives ``pin_match.contract.registry`` itself
(so a monkeypatch through either name is seen by both), with a ``FutureWarning`` naming
the new path, as timm does for moved modules. Caches do not depend on module paths: a
matcher's id hashes its name, version, config and weights only.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings

MOVED = {
    "pin_match.analysis": "pin_match.evaluation.analysis",
    "pin_match.bench": "pin_match.evaluation.bench",
    "pin_match.catalog": "pin_match.cli.catalog",
    "pin_match.cli_eval": "pin_match.cli.evaluation",
    "pin_match.cli_train": "pin_match.cli.training",
    "pin_match.crops": "pin_match.contract.crops",
    "pin_match.distributed": "pin_match.scoring.cluster",
    "pin_match.features": "pin_match.training.features",
    "pin_match.frameset": "pin_match.data.frameset",
    "pin_match.frameset_writer": "pin_match.data.writer",
    "pin_match.head": "pin_match.nn.head",
    "pin_match.importer": "pin_match.data.importer",
    "pin_match.labels": "pin_match.evaluation.labels",
    "pin_match.locate": "pin_match.scoring.cache",
    "pin_match.matcher": "pin_match.contract.matcher",
    "pin_match.metrics": "pin_match.evaluation.metrics",
    "pin_match.plots": "pin_match.evaluation.plots",
    "pin_match.realset": "pin_match.data.realset",
    "pin_match.registry": "pin_match.contract.registry",
    "pin_match.report": "pin_match.evaluation.report",
    "pin_match.scoretable": "pin_match.scoring.table",
    "pin_match.sigma": "pin_match.evaluation.sigma",
    "pin_match.similarity": "pin_match.evaluation.similarity",
    "pin_match.sweep": "pin_match.evaluation.sweep",
    "pin_match.synth": "pin_match.data.synth",
    "pin_match.tables": "pin_match.evaluation.tables",
    "pin_match.testing": "pin_match.contract.testing",
    "pin_match.train_config": "pin_match.training.config",
    "pin_match.tuning": "pin_match.evaluation.tuning",
    "pin_match.weights": "pin_match.contract.weights",
}


def new_name(old: str) -> str | None:
    """The current path of a moved module or of a module inside a moved package (pin_match.synth.objects)."""
    for before, after in MOVED.items():
        if old == before or old.startswith(before + "."):
            return after + old[len(before):]
    return None


class _AliasLoader(importlib.abc.Loader):
    def create_module(self, spec):
        return None

    def exec_module(self, module) -> None:
        target = new_name(module.__name__)
        warnings.warn(f"{module.__name__} moved to {target}; the old path will be removed in a later release",
                      FutureWarning, stacklevel=2)
        # the import system returns what sys.modules holds under the old name once this returns
        sys.modules[module.__name__] = importlib.import_module(target)


class _AliasFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        if not fullname.startswith("pin_match.") or new_name(fullname) is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader())


def install() -> None:
    if not any(isinstance(f, _AliasFinder) for f in sys.meta_path):
        # first: a submodule of a moved package (pin_match.synth.objects) would otherwise be found through its
        # alias parent's __path__ and loaded a second time under the old name
        sys.meta_path.insert(0, _AliasFinder())
