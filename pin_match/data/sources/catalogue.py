"""The data-source interface and the catalogue that finds a source by name.

A source is what turns something (a generator, photos shipped with pin_match, a downloaded
repository) into a frame-set. Each one registers one ``DataSource``; ``pin-match data list /
prepare / build`` and the library reach every source the same way:

- ``build(out, variant, seed, src=...)`` writes a frame-set (through ``FrameSetWriter``, so
  validation, fingerprints and atomic writes come for free);
- ``prepare(inputs, out)``, for a source whose photos are downloaded, writes the source folder
  ``build`` reads (``pin_match.data.sources.photo_folder``) from a checkout.

Found as matchers are (``pin_match.contract.discovery``): a built-in is a module of
``pin_match.data.sources`` that calls ``register`` as it is imported, and every module of that
package is imported the first time a name is listed or asked for, so a new file there is all a
built-in needs. A third-party package adds a source through the ``pin_match.data_sources``
entry-point group, naming its ``DataSource`` (``my-source = "my_package.source:SOURCE"``),
loaded only when its name is asked for. The rules every source shares (a known variant, a
source folder where one is needed and none where it is not, one source per name) are checked
here once.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib.metadata import EntryPoint
from pathlib import Path

from pin_match.contract import discovery
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError

# what a source's build does with a source folder (--src)
SRC_NONE, SRC_OPTIONAL, SRC_REQUIRED = "none", "optional", "required"
ENTRY_POINT_GROUP = "pin_match.data_sources"
BUILTIN_PACKAGE = "pin_match.data.sources"  # every module in it is imported before a name is listed or looked up


class DataSourceError(PinMatchError, ValueError):
    """A data source that does not exist, or a request it cannot serve (a variant, a source folder)."""


@dataclass(frozen=True)
class DataSource:
    """One source of frame-sets: what it is, under which licence, and how to prepare and build it.

    ``make(out, *, variant, seed, src, overwrite)`` and ``make_source(*inputs, out, overwrite)``
    are the source module's own functions; ``build`` and ``prepare`` check the request first.
    """

    name: str
    summary: str  # one line for `pin-match data list`
    licence: str
    variants: tuple[str, ...]  # the first is the default
    make: Callable[..., FrameSet]
    src: str = SRC_NONE  # SRC_OPTIONAL: without one, the folder shipped with pin_match
    prepare_inputs: tuple[str, ...] = ()  # what prepare reads, in order (checkouts, a source folder)
    make_source: Callable[..., Path] | None = None

    def build(self, out: str | Path, variant: str | None = None, seed: int = 0, *, src: str | Path | None = None,
              overwrite: bool = False) -> FrameSet:
        """Write this source's frame-set of ``variant`` (default: the first) to ``out`` and return it loaded."""
        variant = variant or self.variants[0]
        if variant not in self.variants:
            raise DataSourceError(f"source {self.name!r} has no variant {variant!r}; choose one of "
                                  f"{list(self.variants)}")
        if src is not None and self.src == SRC_NONE:
            raise DataSourceError(f"source {self.name!r} reads no source folder: leave out src ({src})")
        if src is None and self.src == SRC_REQUIRED:
            raise DataSourceError(f"source {self.name!r} builds from a prepared source folder: run "
                                  f"`pin-match data prepare {self.name} {' '.join(self.prepare_inputs)} --out SRC`, "
                                  f"then pass --src SRC")
        return self.make(Path(out), variant=variant, seed=seed, src=None if src is None else Path(src),
                         overwrite=overwrite)

    def prepare(self, inputs: Sequence[str | Path], out: str | Path, *, overwrite: bool = False) -> Path:
        """Write the source folder ``out`` from ``inputs`` (``prepare_inputs``, in that order)."""
        if self.make_source is None:
            raise DataSourceError(f"source {self.name!r} needs no preparing: build it directly")
        if len(inputs) != len(self.prepare_inputs):
            raise DataSourceError(f"preparing {self.name!r} reads {len(self.prepare_inputs)} input(s) "
                                  f"({' '.join(self.prepare_inputs)}), got {len(inputs)}")
        return self.make_source(*(Path(p) for p in inputs), Path(out), overwrite=overwrite)


_CATALOGUE: dict[str, DataSource] = {}


def register(source: DataSource) -> DataSource:
    """Add ``source`` under its name; a second, different source of that name is refused."""
    known = _CATALOGUE.get(source.name)
    if known is not None and known != source:
        raise DataSourceError(f"data source {source.name!r} is already registered (by {known.make.__module__})")
    _CATALOGUE[source.name] = source
    return source


def get(name: str) -> DataSource:
    """The source registered as ``name``, or an error listing the known ones."""
    _import_builtins()
    if name not in _CATALOGUE:
        ep = _entry_points().get(name)
        if ep is not None:
            _load(ep)
    try:
        return _CATALOGUE[name]
    except KeyError:
        raise DataSourceError(f"unknown data source {name!r}; known: {', '.join(names())}") from None


def names() -> list[str]:
    """Every source's name, built-in or declared by an entry point, sorted."""
    _import_builtins()
    declared = _entry_points()
    for name, ep in declared.items():
        if name in _CATALOGUE:  # the same source again is harmless; another one under a held name is refused
            _load(ep)
    return sorted(set(_CATALOGUE) | set(declared))


def _import_builtins() -> None:
    discovery.import_package(BUILTIN_PACKAGE, DataSourceError, "data sources")


def _entry_points() -> dict[str, EntryPoint]:
    return discovery.declared(ENTRY_POINT_GROUP, DataSourceError, "data source")


def _load(ep: EntryPoint) -> None:
    """Register the ``DataSource`` an entry point names, or say what is wrong with the entry point."""
    where = f"data source {discovery.described(ep)}"
    source = discovery.load(ep, DataSourceError, "data source")
    if not isinstance(source, DataSource):
        raise DataSourceError(f"{where} names a {type(source).__name__}, not a DataSource")
    if source.name != ep.name:
        raise DataSourceError(f"{where} names the source {source.name!r}; the entry point's name must "
                              f"be the source's")
    try:
        register(source)
    except DataSourceError as exc:
        raise DataSourceError(f"{where}: {exc}; give it another name") from None
