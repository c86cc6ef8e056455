"""Frozen patch features computed once per (backbone config, frame-set), memory-mapped for training heads.

A trained head sees the same inputs the backbone's matcher sees: every frame crop under
the matcher's crop policy, squashed to the backbone's input, and every reference view
with its alpha mask on the patch grid. Running the backbone dominates the cost of
training a head, so the tokens are stored once (float16 ``.npy`` files read with
``mmap_mode``) together with per-patch ground truth (which object covers a patch, and how
much of it); heads and experiments read the store and never run the backbone again.

The store lives in ``<out>/<matcher id>/<frame-set fingerprint>/``: the matcher id
carries the backbone, its config hash and its weights' identity, so two configs never
share a store. It is built in a temporary folder and renamed into place, so a killed
build leaves nothing that opens; opening it for another frame-set is an error.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pin_match import atomic, outputs
from pin_match.contract.crops import crop_boxes
from pin_match.contract.matcher import N_VIEWS, Matcher
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.matchers.common.patch import alpha_to_grid, patch_matcher
from pin_match.scoring.cache import cache_dir

STORE_VERSION = 1
META = "store.json"
CROPS = "crops.parquet"
FRAME_TOKENS = "frames.npy"        # (n_crops, grid * grid, dim) float16
PATCH_OBJECT = "patch_object.npy"  # (n_crops, grid * grid) int32: index into objects, -1 = no object
PATCH_COVER = "patch_cover.npy"    # (n_crops, grid * grid) float16: fraction of the patch that object covers
REF_TOKENS = "refs.npy"            # (n_objects, 3, grid * grid, dim) float16
REF_ALPHA = "ref_alpha.npy"        # (n_objects, 3, grid * grid) float32: alpha on the grid (prototype weights)


class FeatureStoreError(PinMatchError, ValueError):
    """A feature store cannot be built or used (no patch features, another frame-set, incomplete)."""


@dataclass
class FeatureStore:
    """An opened store: tables in memory, token arrays memory-mapped (read-only)."""

    root: Path
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

    @classmethod
    def open(cls, root: str | Path, fs: FrameSet | None = None) -> FeatureStore:
        """Open a finished store; with ``fs``, refuse a store built for another frame-set."""
        root = Path(root)
        if not (root / META).exists():
            raise FeatureStoreError(f"no feature store at {root} (missing {META}): run pin-match features first")
        meta = atomic.read_json(root / META, FeatureStoreError, "feature store metadata")
        if meta.get("version") != STORE_VERSION:
            raise FeatureStoreError(f"feature store {root} has version {meta.get('version')}, this pin_match "
                                    f"reads version {STORE_VERSION}: rebuild it with pin-match features")
        if fs is not None and meta.get("frameset_fingerprint") != fs.fingerprint:
            raise FeatureStoreError(
                f"feature store {root} was built for frame-set {meta.get('frameset_root')} (fingerprint "
                f"{meta.get('frameset_fingerprint')}), not for {fs.root} (fingerprint {fs.fingerprint}); "
                f"run pin-match features {fs.root} --backbone {meta.get('backbone')}")
        crops = pd.read_parquet(root / CROPS)

        def load(name: str) -> np.ndarray:
            return np.load(root / name, mmap_mode="r")

        return cls(root, meta, crops, list(meta["objects"]), load(FRAME_TOKENS), load(PATCH_OBJECT),
                   load(PATCH_COVER), load(REF_TOKENS), load(REF_ALPHA))


def patch_coverage(mask: np.ndarray, values: list[int], grid: int) -> np.ndarray:
    """(len(values), grid, grid): the fraction of each patch's pixels carrying each mask value.

    The crop is squashed to the backbone's square input, so patch (i, j) covers the crop's
    i-th of ``grid`` row bands and j-th column band; OpenCV's area resampling gives exactly
    that fraction, also when the crop side is not a multiple of the grid.
    """
    import cv2

    out = np.zeros((len(values), grid, grid), np.float32)
    for k, value in enumerate(values):
        inside = (mask == value).astype(np.float32)
        out[k] = cv2.resize(inside, (grid, grid), interpolation=cv2.INTER_AREA)
    return out


def _crop_labels(mask: np.ndarray, legend: dict[int, int], grid: int) -> tuple[np.ndarray, np.ndarray]:
    """Per patch, the object covering most of it (index into the store's objects, -1 none) and its coverage."""
    values = [v for v in legend if (mask == v).any()]
    obj = np.full(grid * grid, -1, np.int32)
    cover = np.zeros(grid * grid, np.float16)
    if values:
        cov = patch_coverage(mask, values, grid).reshape(len(values), -1)
        best = cov.argmax(0)
        top = cov[best, np.arange(cov.shape[1])]
        hit = top > 0
        obj[hit] = np.array([legend[v] for v in values], np.int32)[best[hit]]
        cover[:] = top.astype(np.float16)
    return obj, cover


@dataclass(frozen=True)
class _Plan:
    """What one store build encodes: the matcher, the frame-set and the split's part of it, its crops, the objects."""

    matcher: Matcher
    fs: FrameSet
    part: FrameSet
    split: str | None
    policy: str
    crops: pd.DataFrame
    objects: list[str]


def build_features(frameset: FrameSet | str | Path, backbone: str, *, overrides: dict[str, Any] | None = None,
                   out: str | Path = outputs.FEATURES, split: str | None = None, batch_size: int = 8,
                   progress: bool = True) -> FeatureStore:
    """Encode every frame crop and reference view once (or find the finished store) and open it.

    ``split`` limits the frames (references of every object are always stored, so a head
    trained on one split can be evaluated from the store on another).
    """
    fs = frameset if isinstance(frameset, FrameSet) else FrameSet.load(frameset)
    matcher = patch_matcher(backbone, **(overrides or {}))
    root = cache_dir(out, matcher.id, fs.fingerprint) / (split or "all")
    if (root / META).exists():
        return FeatureStore.open(root, fs)
    part = fs.split(split)
    policy = getattr(matcher.cfg, "crops", "whole")
    frames = part.frames.sort_values(["episode_id", "step"]).reset_index(drop=True)
    plan = _Plan(matcher, fs, part, split, policy, _crop_table(frames, policy), sorted(fs.objects.object_id))
    atomic.ensure_dir(root.parent)
    tmp = Path(tempfile.mkdtemp(prefix=f".{root.name}.", suffix=".tmp", dir=root.parent))
    try:
        dim, t_refs = _encode_references(tmp, plan, progress)
        t_frames = _encode_frames(tmp, plan, dim, batch_size, progress)
        atomic.write_parquet(tmp / CROPS, plan.crops)
        meta = _store_meta(plan, dim, t_refs, t_frames)
        atomic.write_text(tmp / META, json.dumps(json.loads(json.dumps(meta, default=str)), indent=2) + "\n")
        try:
            os.replace(tmp, root)
        except OSError:
            if not (root / META).exists():  # not a concurrent build that finished first
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return FeatureStore.open(root, fs)


def _crop_table(frames: pd.DataFrame, policy: str) -> pd.DataFrame:
    """One row per crop of every frame under the matcher's crop policy, in store order."""
    rows = []
    for f in frames.itertuples(index=False):
        for k, box in enumerate(crop_boxes(int(f.height), int(f.width), policy)):
            rows.append(dict(crop_index=len(rows), frame_id=f.frame_id, episode_id=f.episode_id, step=int(f.step),
                             split=f.split, crop=k, x0=box.x0, y0=box.y0, width=box.width, height=box.height))
    return pd.DataFrame(rows, columns=["crop_index", "frame_id", "episode_id", "step", "split", "crop", "x0", "y0",
                                       "width", "height"])


def _encode_references(tmp: Path, plan: _Plan, progress: bool) -> tuple[int, float]:
    """REF_TOKENS and REF_ALPHA for every object; returns the token width and the seconds taken."""
    from tqdm.auto import tqdm

    fs, matcher, objects = plan.fs, plan.matcher, plan.objects
    enc, t0 = matcher.backbone, time.perf_counter()
    grid = int(enc.grid)
    probe = enc.encode([fs.target(objects[0]).views[0][..., :3]]).patches
    if probe.ndim != 3 or probe.shape[1] != grid * grid:
        raise FeatureStoreError(f"backbone of {matcher.id} returned patch tokens of shape {tuple(probe.shape)}, "
                                f"expected (1, {grid * grid}, dim)")
    dim = int(probe.shape[2])
    refs = np.lib.format.open_memmap(tmp / REF_TOKENS, "w+", np.float16, (len(objects), N_VIEWS, grid * grid, dim))
    ref_alpha = np.zeros((len(objects), N_VIEWS, grid * grid), np.float32)
    for i, object_id in enumerate(tqdm(objects, desc="features: references", disable=not progress)):
        views = fs.target(object_id).views
        refs[i] = enc.encode([v[..., :3] for v in views]).patches.numpy().astype(np.float16)
        ref_alpha[i] = np.stack([alpha_to_grid(v[..., 3], grid).numpy().reshape(-1) for v in views])
    np.save(tmp / REF_ALPHA, ref_alpha)
    refs.flush()
    return dim, time.perf_counter() - t0


def _encode_frames(tmp: Path, plan: _Plan, dim: int, batch_size: int, progress: bool) -> float:
    """FRAME_TOKENS with each crop's per-patch ground truth (PATCH_OBJECT, PATCH_COVER); returns the seconds taken."""
    from tqdm.auto import tqdm

    part, matcher, crops, objects = plan.part, plan.matcher, plan.crops, plan.objects
    enc, t0 = matcher.backbone, time.perf_counter()
    grid = int(enc.grid)
    obj_index = {o: i for i, o in enumerate(objects)}
    legends = {fid: {int(v): obj_index[o] for v, o in zip(g.mask_value, g.object_id) if o in obj_index}
               for fid, g in part.visibility.groupby("frame_id")}
    tokens = np.lib.format.open_memmap(tmp / FRAME_TOKENS, "w+", np.float16, (len(crops), grid * grid, dim))
    patch_obj = np.lib.format.open_memmap(tmp / PATCH_OBJECT, "w+", np.int32, (len(crops), grid * grid))
    patch_cov = np.lib.format.open_memmap(tmp / PATCH_COVER, "w+", np.float16, (len(crops), grid * grid))
    by_frame = crops.groupby("frame_id", sort=False).crop_index.apply(list)
    frame_ids = list(dict.fromkeys(crops.frame_id))
    bar = tqdm(total=len(frame_ids), desc=f"features: {matcher.id}", unit="frame", disable=not progress)
    for start in range(0, len(frame_ids), batch_size):
        batch = frame_ids[start:start + batch_size]
        images, idx = [], []
        for fid in batch:
            image, mask = part.image(fid), part.instance_mask(fid)
            for ci in by_frame[fid]:
                c = crops.iloc[ci]
                window = (slice(c.y0, c.y0 + c.height), slice(c.x0, c.x0 + c.width))
                images.append(np.ascontiguousarray(image[window]))
                patch_obj[ci], patch_cov[ci] = _crop_labels(mask[window], legends.get(fid, {}), grid)
                idx.append(ci)
        tokens[idx[0]:idx[-1] + 1] = enc.encode(images).patches.numpy().astype(np.float16)
        bar.update(len(batch))
    bar.close()
    for arr in (tokens, patch_obj, patch_cov):
        arr.flush()
    return time.perf_counter() - t0


def _store_meta(plan: _Plan, dim: int, t_refs: float, t_frames: float) -> dict:
    import pin_match

    matcher, fs, crops = plan.matcher, plan.fs, plan.crops
    n_frames = crops.frame_id.nunique()
    return dict(version=STORE_VERSION, backbone=matcher.display_name, matcher_id=matcher.id,
                config=matcher.cfg.hashed_dict(), frameset_fingerprint=fs.fingerprint, frameset_root=str(fs.root),
                split=plan.split or "all", crops_policy=plan.policy, grid=int(matcher.backbone.grid), dim=dim,
                input_size=int(getattr(matcher.backbone, "input_size", 0)), objects=plan.objects, n_crops=len(crops),
                n_frames=n_frames, seconds_references=round(t_refs, 2), seconds_frames=round(t_frames, 2),
                frames_per_second=round(n_frames / max(t_frames, 1e-9), 3), pin_match_version=pin_match.__version__,
                created=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))
