"""The paper's similarity analysis: how alike the frontal references of one category are, versus others.

A matcher that embeds same-category objects almost identically cannot tell the target
from its same-category distractors, whatever the threshold; this table shows where that
happens. Only view 0 (frontal) of every object of one split is embedded, with the
matcher's own global embedding (``Matcher.embed_reference``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic
from pin_match.contract.matcher import Matcher
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError


class SimilarityError(PinMatchError, ValueError):
    """No objects to compare, or a matcher whose embedding of one is unusable."""


def embeddings(fs: FrameSet, matcher: Matcher, split: str | None = "val") -> tuple[pd.DataFrame, np.ndarray]:
    """The split's objects (object_id, category) and their L2-normalised frontal embeddings, one row each."""
    objects = fs.objects if split in (None, "all") else fs.objects[fs.objects.split == split]
    objects = objects.sort_values(["category", "object_id"]).reset_index(drop=True)
    if objects.empty:
        raise SimilarityError(f"frame-set {fs.root} has no objects of split {split!r}")
    vectors = np.stack([np.asarray(matcher.embed_reference(fs.target(oid).views[0]), np.float64).reshape(-1)
                        for oid in objects.object_id])
    norms = np.linalg.norm(vectors, axis=1, keepdims=True)
    if (norms == 0).any():
        raise SimilarityError(f"{matcher.display_name} embedded object {objects.object_id[int(np.argmin(norms))]!r} "
                         "as a zero vector")
    return objects[["object_id", "category"]], vectors / norms


def similarity(fs: FrameSet, matcher: Matcher, split: str | None = "val") -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per category: intra (mean cosine over same-category pairs, self-pairs excluded) and inter (mean
    over every pair with an object of another category); and the category x category mean-cosine matrix.

    A category with a single object has no intra pairs: NaN (undefined).
    """
    objects, vectors = embeddings(fs, matcher, split)
    return similarity_tables(objects.category.to_numpy(), vectors @ vectors.T)


def similarity_tables(categories: np.ndarray, cosine: np.ndarray) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The two tables from per-object categories and the object x object cosine matrix."""
    names = sorted(set(categories))
    member = np.stack([categories == c for c in names]).astype(np.float64)  # categories x objects
    off_diagonal = cosine - np.diag(np.diag(cosine))
    sums = member @ off_diagonal @ member.T
    sizes = member.sum(axis=1)
    pairs = np.outer(sizes, sizes) - np.diag(sizes)  # ordered pairs of distinct objects
    with np.errstate(divide="ignore", invalid="ignore"):
        matrix = np.where(pairs > 0, sums / np.where(pairs > 0, pairs, 1), np.nan)
        cross_sum = sums.sum(axis=1) - np.diag(sums)
        cross_pairs = pairs.sum(axis=1) - np.diag(pairs)
        inter = np.where(cross_pairs > 0, cross_sum / np.where(cross_pairs > 0, cross_pairs, 1), np.nan)
    table = pd.DataFrame({"n_objects": sizes.astype(np.int64), "intra": np.diag(matrix), "inter": inter},
                         index=pd.Index(names, name="category"))
    return table, pd.DataFrame(matrix, index=pd.Index(names, name="category"), columns=names)


def write_similarity(table: pd.DataFrame, matrix: pd.DataFrame, out_dir: str | Path, title: str = "") -> list[Path]:
    """similarity.csv, similarity_matrix.csv, similarity.md and a heatmap similarity.png."""
    from pin_match.evaluation.core.tables import markdown_table

    out = Path(out_dir)
    files = [out / n for n in ("similarity.csv", "similarity_matrix.csv", "similarity.md", "similarity.png")]
    atomic.write_text(files[0], table.to_csv())
    atomic.write_text(files[1], matrix.to_csv())
    shown = table.round(3).rename(columns={"n_objects": "Objects", "intra": "Intra", "inter": "Inter"})
    atomic.write_text(files[2], (f"# {title}\n\n" if title else "") + markdown_table(shown) + "\n")
    _heatmap(matrix, files[3], title)
    return files


def _heatmap(matrix: pd.DataFrame, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(matrix)
    fig, ax = plt.subplots(figsize=(2 + 0.45 * n, 1.5 + 0.45 * n))
    try:
        image = ax.imshow(matrix.to_numpy(), cmap="viridis", vmin=-1 if (matrix.to_numpy() < 0).any() else 0, vmax=1)
        ax.set_xticks(range(n), matrix.columns, rotation=45, ha="right")
        ax.set_yticks(range(n), matrix.index)
        for i in range(n):
            for j in range(n):
                v = matrix.iat[i, j]
                ax.text(j, i, "n/a" if np.isnan(v) else f"{v:.2f}", ha="center", va="center", fontsize=7,
                        color="white" if np.isnan(v) or v < 0.5 else "black")
        fig.colorbar(image, ax=ax, label="mean cosine")
        ax.set_title(title)
        fig.tight_layout()
        with atomic.atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=120)
    finally:
        plt.close(fig)
