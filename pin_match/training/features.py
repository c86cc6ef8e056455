"""Frozen patch features computed once per (backbone config, frame-set), memory-mapped for training heads.

A trained head sees the same inputs the backbone's matcher sees: every frame crop under
the matcher's crop policy, squashed to the backbone's input, and every reference view
with its alpha mask on the patch grid. Running the backbone dominates the cost of
training a head, so the tokens are stored once (float16 ``.npy`` files read with
``mmap_mode``) together with per-patch ground truth (which object covers a patch, and how
much of it); heads and experiments read the store and never run the backbone again.

The frames are a product of the scoring engine (``frame_tokens.FrameTokens``): chunks per
episode (a killed build resumes), locks, Dask, the progress bar and the score cache's rule,
so the store lives in ``<out>/features-<matcher id>/<frame-set fingerprint>/`` (the matcher
id carries the backbone, its config hash and its weights' identity: two configs never share
a store) as ``features_<split>.parquet``, the crop table whose metadata describes the store,
with its arrays beside it. The reference tokens of every object are computed first, once per
folder. Opening a store for another frame-set is an error, and so is a damaged one, naming the file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pin_match import atomic, outputs
from pin_match.contract.matcher import N_VIEWS, Matcher
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.matchers.common.patch import alpha_to_grid, patch_matcher
from pin_match.scoring.api import run_jobs
from pin_match.scoring.cache import cache_dir, read_meta, table_name
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.product import Job
from pin_match.training.frame_tokens import (
    ARRAYS,
    FRAME_TOKENS,
    KIND,
    PATCH_COVER,
    PATCH_OBJECT,
    STORE_VERSION,
    FrameTokens,
    array_path,
    store_folder,
)

REF_TOKENS = "refs.npy"            # (n_objects, 3, grid * grid, dim) float16
REF_ALPHA = "ref_alpha.npy"        # (n_objects, 3, grid * grid) float32: alpha on the grid (prototype weights)


class FeatureStoreError(PinMatchError, ValueError):
    """A feature store cannot be built or used (no patch features, another frame-set, damaged)."""


class DamagedStoreError(FeatureStoreError):
    """A file of a feature store cannot be read or has the wrong shape (``build_features`` writes it again)."""


@dataclass
class FeatureStore:
    """An opened store: the crop table in memory, the token arrays memory-mapped (read-only)."""

    path: Path                   # the crop table, features_<split>.parquet; its arrays and references lie beside it
    meta: dict
    crops: pd.DataFrame          # one row per crop: crop_index, frame_id, episode_id, step, split, crop, box
    objects: list[str]           # object ids, the order of refs / ref_alpha and of patch_object's indices
    frames: np.ndarray           # FRAME_TOKENS
    patch_object: np.ndarray
    patch_cover: np.ndarray
    refs: np.ndarray
    ref_alpha: np.ndarray

    @property
    def grid(self) -> int:
        return int(self.meta["grid"])

    @property
    def dim(self) -> int:
        return int(self.meta["dim"])

    @property
    def backbone_id(self) -> str:
        return str(self.meta["matcher_id"])

    def object_index(self) -> dict[str, int]:
        return {o: i for i, o in enumerate(self.objects)}

    def files(self) -> list[Path]:
        """The files this store reads (the chunks it was assembled from are the engine's)."""
        return [self.path, *(array_path(self.path, name) for name in ARRAYS),
                self.path.parent / REF_TOKENS, self.path.parent / REF_ALPHA]

    @classmethod
    def open(cls, path: str | Path, fs: FrameSet | None = None) -> FeatureStore:
        """Open a finished store by its crop table; with ``fs``, refuse a store built for another frame-set."""
        path = Path(path)
        meta = _store_meta(path)
        if fs is not None and meta.get("frameset_fingerprint") != fs.fingerprint:
            raise FeatureStoreError(
                f"feature store {path} was built for frame-set {meta.get('frameset_name')!r} (fingerprint "
                f"{meta.get('frameset_fingerprint')}), not for {fs.root} (fingerprint {fs.fingerprint}); "
                f"run pin-match features {fs.root} --backbone {meta.get('backbone')}")
        crops = _read(path, pd.read_parquet)
        shapes = FrameTokens(int(meta["grid"]), int(meta["dim"]))
        arrays = [_array(array_path(path, name), (len(crops), *shapes.row_shape(name)))
                  for name in (FRAME_TOKENS, PATCH_OBJECT, PATCH_COVER)]
        refs, ref_alpha = _references(path.parent, len(meta["objects"]))
        if refs.shape[2:] != shapes.row_shape(FRAME_TOKENS):
            raise DamagedStoreError(f"feature store {path}: its references {path.parent / REF_TOKENS} hold tokens of "
                                    f"shape {refs.shape[2:]}, its frames {shapes.row_shape(FRAME_TOKENS)}: run "
                                    "pin-match features again")
        return cls(path, meta, crops, list(meta["objects"]), *arrays, refs, ref_alpha)


def _store_meta(path: Path) -> dict:
    if not path.exists():
        raise FeatureStoreError(f"no feature store at {path}: run pin-match features first")
    meta = read_meta(path)
    if meta is None:
        raise DamagedStoreError(f"cannot read the feature store {path} (damaged, or not a pin_match table): "
                                "run pin-match features again to rewrite it")
    if meta.get("kind") != KIND or meta.get("version") != STORE_VERSION:
        raise FeatureStoreError(f"{path} is no feature store of version {STORE_VERSION} (it holds "
                                f"{meta.get('kind', 'scores')!r}, version {meta.get('version')}): rebuild it with "
                                "pin-match features")
    return meta


def _read(path: Path, reader: Any) -> Any:
    """``reader(path)``, its failure on a damaged file a DamagedStoreError naming it."""
    try:
        return reader(path)
    except (OSError, ValueError) as exc:  # pyarrow's and numpy's errors on a damaged file are one or the other
        raise DamagedStoreError(f"cannot read the feature store file {path} ({type(exc).__name__}: {exc}): "
                                "run pin-match features again to rewrite it") from exc


def _array(path: Path, shape: tuple[int, ...]) -> np.ndarray:
    """A store's array, memory-mapped, in the shape its crop table and metadata say."""
    array = _read(path, lambda p: np.load(p, mmap_mode="r"))
    if array.shape != shape:
        raise DamagedStoreError(f"feature store file {path} has shape {array.shape}, expected {shape}: "
                                "run pin-match features again to rewrite it")
    return array


def _references(root: Path, n_objects: int) -> tuple[np.ndarray, np.ndarray]:
    """REF_TOKENS and REF_ALPHA of the folder ``root``, memory-mapped and checked against each other."""
    refs = _read(root / REF_TOKENS, lambda p: np.load(p, mmap_mode="r"))
    ref_alpha = _read(root / REF_ALPHA, lambda p: np.load(p, mmap_mode="r"))
    if refs.ndim != 4 or refs.shape[:2] != (n_objects, N_VIEWS) or ref_alpha.shape != refs.shape[:3]:
        raise DamagedStoreError(f"feature store references {root / REF_TOKENS} {refs.shape} and {root / REF_ALPHA} "
                                f"{ref_alpha.shape} do not fit {n_objects} objects of {N_VIEWS} views: run "
                                "pin-match features again to rewrite them")
    return refs, ref_alpha


def store_path(out: str | Path, matcher: Matcher, fs: FrameSet, split: str | None = None) -> Path:
    """Where ``build_features`` puts the store of this backbone config, frame-set and split (the engine's rule)."""
    if split in (None, "all"):  # as ``run_jobs`` names it: a view of one split is that split
        split = fs.split_name
    return cache_dir(out, store_folder(matcher), fs.fingerprint) / table_name(split, None, FrameTokens.prefix)


def build_features(frameset: FrameSet | str | Path, backbone: str, *, overrides: dict[str, Any] | None = None,
                   out: str | Path = outputs.FEATURES, split: str | None = None,
                   run: RunOptions = DEFAULT_RUN) -> FeatureStore:
    """Encode every frame crop and reference view once (or find them) and open the store.

    ``split`` limits the frames (references of every object are always stored, so a head
    trained on one split can be evaluated from the store on another). The frames run through
    the scoring engine with ``run`` (batch size, progress, a Dask client); a store whose arrays
    are damaged is assembled again from its chunks.
    """
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    matcher = patch_matcher(backbone, **(overrides or {}))
    root = atomic.ensure_dir(cache_dir(out, store_folder(matcher), fs.fingerprint))
    refs, _ = _reference_tokens(root, matcher, fs, run.progress)
    job = Job(matcher, FrameTokens(math.isqrt(refs.shape[2]), refs.shape[3]))
    (path,) = run_jobs(fs, [job], split=split, out=out, run=run)
    try:
        return FeatureStore.open(path, fs)
    except DamagedStoreError:
        path.unlink(missing_ok=True)  # not this run's table any more: the engine assembles it again
        (path,) = run_jobs(fs, [job], split=split, out=out, run=run)
        return FeatureStore.open(path, fs)


def _reference_tokens(root: Path, matcher: Matcher, fs: FrameSet, progress: bool) -> tuple[np.ndarray, np.ndarray]:
    """The folder's REF_TOKENS and REF_ALPHA for every object, encoded when missing or damaged."""
    objects = sorted(fs.objects.object_id)
    try:
        return _references(root, len(objects))
    except DamagedStoreError:
        pass  # missing or damaged: encoded (again) below
    from tqdm.auto import tqdm

    enc = matcher.backbone
    grid = int(enc.grid)
    ref_alpha = np.zeros((len(objects), N_VIEWS, grid * grid), np.float32)
    with atomic.atomic_path(root / REF_TOKENS) as tmp:
        refs = None
        for i, object_id in enumerate(tqdm(objects, desc="features: references", disable=not progress)):
            views = fs.target(object_id).views
            patches = enc.encode([v[..., :3] for v in views]).patches
            if patches.ndim != 3 or patches.shape[:2] != (N_VIEWS, grid * grid):
                raise FeatureStoreError(f"backbone of {matcher.id} returned patch tokens of shape "
                                        f"{tuple(patches.shape)}, expected ({N_VIEWS}, {grid * grid}, dim)")
            if refs is None:  # the token width is the backbone's first answer's
                refs = np.lib.format.open_memmap(tmp, "w+", np.float16, (len(objects), *patches.shape))
            refs[i] = patches.numpy().astype(np.float16)
            ref_alpha[i] = np.stack([alpha_to_grid(v[..., 3], grid).numpy().reshape(-1) for v in views])
        refs.flush()
    with atomic.atomic_path(root / REF_ALPHA) as tmp, open(tmp, "wb") as fh:  # a file: np.save adds no suffix
        np.save(fh, ref_alpha)
    return _references(root, len(objects))
