"""``pin-match inspect``: one HTML page of a frame-set itself, before any matcher sees it.

A matcher can only be as good as its references and ground truth, so the page shows every
object's reference views on a checkerboard (a cut-out that kept its background, or lost
its object, is flagged and framed in red), a seeded sample of frames per role with the mask
outlines, the counts per split and category, and the target's size per split.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from markupsafe import Markup

from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.labels import frame_labels
from pin_match.evaluation.pages import html
from pin_match.evaluation.pages.gallery import ROLE_NAMES, frame_roles
from pin_match.evaluation.pages.pictures import frame_image, legend, reference_images

PAGE = "index.html"
ASSETS = "inspect_files"
MAX_OBJECTS = 400
FRAMES_PER_ROLE = 8
OPAQUE = 0.97   # a view whose alpha covers more than this is a photo, not a cut-out
EMPTY = 0.02    # ... and less than this has lost its object


def cutout_problems(views: tuple[np.ndarray, ...]) -> list[str]:
    """What is visibly wrong with an object's RGBA views: no cut-out, an empty one, or one photo repeated."""
    problems = []
    for k, view in enumerate(views):
        cover = float((view[..., 3] > 0).mean())
        if cover > OPAQUE:
            problems.append(f"view {k} is not cut out ({cover:.0%} opaque)")
        elif cover < EMPTY:
            problems.append(f"view {k} is almost empty ({cover:.1%} opaque)")
    if len(views) > 1 and all(np.array_equal(views[0], v) for v in views[1:]):
        problems.append(f"the {len(views)} views are one image repeated")
    return problems


def counts(fs: FrameSet, labels: pd.DataFrame | None = None) -> pd.DataFrame:
    """Objects, target episodes and frames per role, per split and target category (``labels``: ``fs``'s frame
    labels with their ``role``, when the caller has them)."""
    labels = labels if labels is not None else role_labels(fs)
    frames = labels.groupby(["split", "target_category", "role"]).size().unstack("role", fill_value=0)
    frames = frames.reindex(columns=list(ROLE_NAMES), fill_value=0).add_prefix("frames: ")
    episodes = fs.episodes.groupby(["split", "target_category"]).size().rename("episodes")
    objects = fs.objects.groupby(["split", "category"]).size().rename("objects")
    objects.index = objects.index.set_names(["split", "target_category"])
    table = pd.concat([objects, episodes, frames], axis=1).fillna(0).astype(np.int64)
    table.index = [f"{split} / {category}" for split, category in table.index]
    return table.rename_axis("split / category")


def role_labels(fs: FrameSet) -> pd.DataFrame:
    """``frame_labels`` of the walks' frames (approach views are not counted) with each frame's role: built once per
    page."""
    labels = frame_labels(fs)
    return labels[~labels["approach"]].assign(role=lambda d: frame_roles(d))


LARGE_PX = 2000  # a target this large is one an instance matcher can be asked to recognise


def target_sizes(labels: pd.DataFrame) -> pd.DataFrame:
    """Per split: how large the target is where it shows (pixels: quantiles), and how many episodes show it large.

    Two splits whose targets differ in size cannot share a sigma: one tuned where targets are
    large meets specks on the other. ``labels``: ``frame_labels`` of the frame-set.
    """
    shown = labels[labels.target_pixels > 0]
    large = shown[shown.target_pixels >= LARGE_PX].groupby(["split", "episode_id"]).size()
    rows = {}
    for split, group in labels.groupby("split"):
        pixels = shown.target_pixels[shown.split == split]
        episodes = group.episode_id.nunique()
        per_episode = large.get(split, pd.Series(dtype=int))
        quantiles = {f"p{q}": float(np.percentile(pixels, q)) if len(pixels) else np.nan for q in (10, 25, 50, 75, 90)}
        rows[split] = {"episodes": episodes, "target frames": len(pixels), **quantiles,
                       f"frames >= {LARGE_PX} px": int((pixels >= LARGE_PX).sum()),
                       "episodes with 3 such frames": int((per_episode >= 3).sum())}
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("split")


def object_figures(fs: FrameSet, assets: html.Assets) -> tuple[list[Markup], int]:
    """One figure per object (capped at ``MAX_OBJECTS``) and how many objects have a visible problem."""
    uses = fs.episodes.target_object_id.value_counts()
    figures, n_bad = [], 0
    for _, obj in fs.objects.sort_values(["category", "object_id"]).iterrows():
        target = fs.target(obj.object_id)
        problems = cutout_problems(target.views)
        n_bad += bool(problems)
        if len(figures) >= MAX_OBJECTS:
            continue
        lines = [f"{obj.object_id} ({obj.category}, {obj.split})",
                 f"target of {int(uses.get(obj.object_id, 0))} episodes", *problems]
        figures.append(html.figure(reference_images(assets, target), lines, "miss" if problems else None))
    return figures, n_bad


def frame_samples(fs: FrameSet, labels: pd.DataFrame, assets: html.Assets, per_role: int, seed: int) -> list[Markup]:
    parts = []
    for role in ROLE_NAMES:
        rows = labels[labels.role == role]
        sample = rows.sample(min(per_role, len(rows)), random_state=seed).sort_values("frame_id")
        parts.append(html.heading(f"Frames showing: {role}", 3))
        parts.append(html.paragraph(f"{len(sample)} of {len(rows)} frames, a seeded random sample.", "note"))
        parts.append(html.gallery([html.figure(
            [frame_image(assets, fs, f.frame_id)],
            [f"frame {f.frame_id}", f"episode {f.episode_id} ({f.split}), step {f.step}",
             f"target category {f.target_category}"]) for _, f in sample.iterrows()]))
    return parts


def write_frameset_page(fs: FrameSet, out_dir: str | Path, *, per_role: int = FRAMES_PER_ROLE,
                        seed: int = 0) -> Path:
    """Write ``index.html`` (and ``inspect_files/``) describing ``fs`` into ``out_dir``; returns the page's path."""
    path = Path(out_dir) / PAGE
    assets = html.Assets(path, ASSETS)
    labels = role_labels(fs)
    figures, n_bad = object_figures(fs, assets)
    shown = f"{len(figures)} of {len(fs.objects)} objects shown" + \
        (f" (capped at {MAX_OBJECTS})" if len(figures) < len(fs.objects) else "")
    parts = [html.definitions([("frame-set", fs.manifest.get("name", "")), ("folder", fs.root),
                               ("fingerprint", fs.fingerprint), ("objects", len(fs.objects)),
                               ("episodes", len(fs.episodes)), ("frames", len(fs.frames))]),
             html.heading("Counts per split and target category"), html.table(counts(fs, labels)),
             html.heading("Target size per split"),
             html.paragraph("Visible pixels of the target in the frames that show it (percentiles), and the "
                            f"episodes that show it at {LARGE_PX} pixels or more in at least three frames.", "note"),
             html.table(target_sizes(labels)),
             html.heading("Every object's reference views"),
             html.paragraph(f"{shown}, on a checkerboard so the cut-out shows. {n_bad} objects have a visible "
                            "problem (red frame: not cut out, empty, or one image repeated).", "note"),
             html.gallery(figures), html.heading("Sample frames per role"),
             legend(points=False),
             *frame_samples(fs, labels, assets, per_role, seed)]
    return html.write_page(path, f"Frame-set {fs.manifest.get('name', '') or fs.root}", parts)
