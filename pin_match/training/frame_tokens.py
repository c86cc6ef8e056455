"""Every frame crop's patch tokens and per-patch ground truth: a per-frame product of the scoring engine.

The feature store's frames are computed like any score table (``scoring.run_jobs``): per-episode
chunk files, so a killed build resumes where it stopped, locks shared with other processes, Dask
with a client, the progress bar, and the cache rule (``<out>/features-<matcher id>/<frame-set
fingerprint>/``, a table counting only when its metadata is this run's). A chunk holds one row per
crop with its tokens as fixed-size float16 lists; the table is the crop table, and ``assemble``
writes the token and ground-truth columns beside it as ``.npy`` files, each renamed into place
before the table. Training reads random crops of an episode every step: a memory-mapped ``.npy``
serves them straight from the page cache as one array, where a parquet column would be decoded
(and held in memory) first.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd
import pyarrow as pa

import pin_match
from pin_match import atomic
from pin_match.contract.crops import crop_boxes
from pin_match.contract.matcher import Matcher, MatcherError
from pin_match.data.frameset import FrameSet
from pin_match.scoring.cache import Shard
from pin_match.scoring.product import Product
from pin_match.scoring.schema import as_stored, encode_meta

STORE_VERSION = 2
KIND = "patch features"
CROP_COLUMNS = ["frame_id", "episode_id", "step", "split", "crop", "x0", "y0", "width", "height"]
FRAME_TOKENS = "frames"        # (n_crops, grid * grid, dim) float16
PATCH_OBJECT = "patch_object"  # (n_crops, grid * grid) int32: index into the store's objects, -1 = no object
PATCH_COVER = "patch_cover"    # (n_crops, grid * grid) float16: fraction of the patch that object covers
ARRAYS = {FRAME_TOKENS: np.float16, PATCH_OBJECT: np.int32, PATCH_COVER: np.float16}
ASSEMBLE_ROWS = 256  # crops per read while assembling: memory stays flat in the number of crops


def store_folder(matcher: Matcher) -> str:
    """The cache folder's name for a backbone config: its own, so a score cache at the same ``out`` is untouched."""
    return f"features-{matcher.id}"


def array_path(table: Path, name: str) -> Path:
    """Where the array ``name`` of the store whose crop table is ``table`` lives: beside it, named after it."""
    return table.with_name(f"{table.stem}.{name}.npy")


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


def crop_labels(mask: np.ndarray, legend: dict[int, int], grid: int) -> tuple[np.ndarray, np.ndarray]:
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


def _fixed(kind: Any, size: int) -> Any:
    """A fixed-size list type whose values are named as parquet stores them, so a chunk reads back in its schema."""
    return pa.list_(pa.field("element", kind), size)


@dataclass(frozen=True)
class FrameTokens(Product):
    """The patch tokens of every crop of every frame under the matcher's crop policy, with per-patch ground truth.

    ``grid`` and ``dim`` are the backbone's (read off its reference tokens), fixing the chunks'
    types. The objects are indexed in the order of the frame-set's sorted object ids, the order
    of the store's reference arrays.
    """

    grid: int
    dim: int
    prefix: ClassVar[str] = "features"

    def folder(self, matcher: Matcher) -> str:
        return store_folder(matcher)

    def compute(self, matcher: Matcher, images: list[np.ndarray]) -> list[Any]:
        """Per frame, its crop boxes and their tokens ((crops, grid * grid, dim) float16), one backbone batch."""
        plans = [crop_boxes(im.shape[0], im.shape[1], matcher.cfg.crops) for im in images]
        flat = [np.ascontiguousarray(box.take(im)) for im, boxes in zip(images, plans) for box in boxes]
        tokens = matcher.backbone.encode(flat).patches.numpy().astype(np.float16)
        if tokens.shape[1:] != (self.grid * self.grid, self.dim):
            raise MatcherError(f"backbone of {matcher.id} returned patch tokens of shape {tuple(tokens.shape)}, "
                               f"expected ({len(flat)}, {self.grid * self.grid}, {self.dim})")
        starts = np.cumsum([0] + [len(boxes) for boxes in plans])
        return [(boxes, tokens[a:b]) for boxes, a, b in zip(plans, starts[:-1], starts[1:])]

    def frames_in_parallel(self, matcher: Matcher) -> bool:
        return False

    def notes(self, matcher: Matcher) -> dict:
        return {}  # the tokens do not depend on the episode's target

    def rows(self, fs: FrameSet, episode: Any, frame_ids: list[str], steps: np.ndarray,
             results: list[Any]) -> pd.DataFrame:
        index = {o: i for i, o in enumerate(sorted(fs.objects.object_id))}
        seen = fs.visibility[fs.visibility.frame_id.isin(frame_ids)]
        legends = {fid: {int(v): index[o] for v, o in zip(g.mask_value, g.object_id) if o in index}
                   for fid, g in seen.groupby("frame_id")}
        rows = []
        for frame_id, step, (boxes, tokens) in zip(frame_ids, steps, results):
            mask = fs.instance_mask(frame_id)
            for k, (box, crop_tokens) in enumerate(zip(boxes, tokens)):
                obj, cover = crop_labels(box.take(mask), legends.get(frame_id, {}), self.grid)
                rows.append(dict(frame_id=frame_id, episode_id=episode.episode_id, step=int(step),
                                 split=str(episode.split), crop=k, x0=box.x0, y0=box.y0, width=box.width,
                                 height=box.height, **{FRAME_TOKENS: crop_tokens.reshape(-1), PATCH_OBJECT: obj,
                                                       PATCH_COVER: cover}))
        return pd.DataFrame(rows, columns=self.schema().names)

    def crop_schema(self) -> Any:
        """The crop table's columns: the chunks' without the arrays."""
        return pa.schema([(c, pa.large_string()) for c in CROP_COLUMNS[:2]] + [("step", pa.int64()),
                          ("split", pa.large_string())] + [(c, pa.int64()) for c in CROP_COLUMNS[4:]])

    def schema(self) -> Any:
        patches = self.grid * self.grid
        return pa.schema(list(self.crop_schema()) + [
            (FRAME_TOKENS, _fixed(pa.float16(), patches * self.dim)), (PATCH_OBJECT, _fixed(pa.int32(), patches)),
            (PATCH_COVER, _fixed(pa.float16(), patches))])

    def meta(self, matcher: Matcher, fs: FrameSet, split: str | None, shard: Shard | None) -> dict:
        return as_stored(dict(kind=KIND, version=STORE_VERSION, backbone=matcher.display_name, matcher_id=matcher.id,
                              config=matcher.cfg.hashed_dict(), frameset_fingerprint=fs.fingerprint,
                              frameset_name=fs.manifest.get("name", ""), split=split or "all",
                              shard=str(shard) if shard else None, crops_policy=matcher.cfg.crops, grid=self.grid,
                              dim=self.dim, objects=sorted(fs.objects.object_id),
                              pin_match_version=pin_match.__version__))

    def assemble(self, final: Path, chunk_files: list[Path], meta: dict) -> None:
        """The arrays (``array_path``) streamed from the chunks, then the crop table with ``crop_index``; each file
        renamed into place whole, the table last, so a table that exists has its arrays."""
        import pyarrow.parquet as pq

        files = [pq.ParquetFile(path) for path in chunk_files]
        n_crops = sum(f.metadata.num_rows for f in files)
        crops = []
        with contextlib.ExitStack() as stack:
            arrays = {name: np.lib.format.open_memmap(stack.enter_context(atomic.atomic_path(array_path(final, name))),
                                                      "w+", dtype, (n_crops, *self.row_shape(name)))
                      for name, dtype in ARRAYS.items()}
            start = 0
            for f in files:
                for batch in f.iter_batches(batch_size=ASSEMBLE_ROWS):
                    stop = start + batch.num_rows
                    for name, array in arrays.items():
                        values = batch.column(name).flatten().to_numpy(zero_copy_only=False)
                        array[start:stop] = values.reshape(batch.num_rows, *self.row_shape(name))
                    crops.append(batch.select(CROP_COLUMNS))
                    start = stop
            for array in arrays.values():
                array.flush()
        table = pa.Table.from_batches(crops, schema=self.crop_schema())
        table = table.add_column(0, "crop_index", pa.array(np.arange(n_crops, dtype=np.int64)))
        with atomic.atomic_path(final) as tmp:
            pq.write_table(table.replace_schema_metadata(encode_meta(meta)), tmp)

    def row_shape(self, name: str) -> tuple[int, ...]:
        """One crop's shape in the array ``name``."""
        patches = self.grid * self.grid
        return (patches, self.dim) if name == FRAME_TOKENS else (patches,)
