"""The verifier's ablation and how far one sigma carries, from cached candidate signals: docs/instance-matchers.md.

Every signal set (each signal alone, each left out, all) is fitted on the train splits of the
development frame-sets and read, with the same cached signals, on every evaluation set: AUROC
of target frames against same-category look-alike frames with its interval (target instances
resampled, ``intervals.bootstrap_ci``, as in every table), and TM / CM at the sigma tuned
(PIN's first-match objective) on the development train splits. The default ``effnet`` comes
from the same tables: the verifier's first candidate is the locate map's best cell, whose
cosine is ``effnet``'s frame score.

``pin-match fit verifier-report --train FS ... --eval FS[:SPLIT] ... [--features DIR] [--json OUT] [--figure PNG]``
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic, outputs
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.intervals import bootstrap_ci, instance_clusters
from pin_match.evaluation.labels import frame_labels
from pin_match.evaluation.metrics import DEFAULT_BOOT, Bootstrap, detection_metrics, frame_arrays, ranking_metrics
from pin_match.evaluation.paired import paired_comparison
from pin_match.evaluation.tuning import sigma_for
from pin_match.fitting.verifier import candidate_table, fit_verifier, frame_scores
from pin_match.matchers.verify import DEFAULT_SIGNALS, SIGNALS, verdict


def signal_sets(signals: Sequence[str] = SIGNALS) -> dict[str, dict]:
    """The ablation's rows as ``verify`` overrides: the default, it without the colour gate, all signals, each alone,
    each left out of all (a set without ``color`` has no gate)."""
    sets = {"default": DEFAULT_SIGNALS, "all": tuple(signals)}
    sets.update({f"{s} alone": (s,) for s in signals})
    sets.update({f"without {s}": tuple(x for x in signals if x != s) for s in signals})
    rows = {label: dict(signals=s) if "color" in s else dict(signals=s, color_gate=0.0) for label, s in sets.items()}
    rows["default, no gate"] = dict(signals=DEFAULT_SIGNALS, color_gate=0.0)
    return rows


def candidate_recall(table: pd.DataFrame, labels: pd.DataFrame, share: float = 0.5) -> float:
    """Share of the target frames where some candidate box holds at least ``share`` of the target's visible pixels:
    what no signal can rescue when it fails."""
    target_frames = set(labels.frame_id[labels.target_visible])
    best = table[table.frame_id.isin(target_frames)].groupby("frame_id").cover.max()
    return float((best.reindex(sorted(target_frames)).fillna(0.0) >= share).mean()) if target_frames else float("nan")


def split_labels(fs: FrameSet, split: str | None) -> pd.DataFrame:
    """``frame_labels`` of the split's frames (all of them for None): built once per set, scored many times."""
    labels = frame_labels(fs)
    return labels if split is None else labels[labels.split == split]


def scored(labels: pd.DataFrame, scores: pd.DataFrame) -> pd.DataFrame:
    """The labelled frames with their score."""
    return labels.merge(scores, on="frame_id", how="inner", validate="one_to_one")


def effnet_scores(table: pd.DataFrame) -> pd.DataFrame:
    """The default ``effnet``'s frame scores: the locate peak of each frame's first candidate."""
    first = table[table.candidate == 0]
    return pd.DataFrame({"frame_id": first.frame_id.to_numpy(), "score": first.proto.to_numpy()})


def report(train: Sequence[str], evals: Sequence[str], features: str | Path = outputs.FEATURES,
           boot: Bootstrap = DEFAULT_BOOT) -> dict:
    """Every signal set and ``effnet`` on every evaluation set (val split where it has one, else all frames)."""
    train_sets = [FrameSet.load(p).split("train") for p in train]
    eval_sets = {}
    for item in evals:
        path, _, split = item.partition(":")
        eval_sets[Path(path).name] = FrameSet.load(path).split(split or None)
    base = create_matcher("verify")
    tables = {name: candidate_table(fs, base, out=features) for name, fs in
              {**{Path(p).name: fs for p, fs in zip(train, train_sets)}, **eval_sets}.items()}
    rows, sigmas = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        specs = {label: fit_verifier(train_sets, Path(tmp) / "v.json", overrides=overrides, out=features)
                 for label, overrides in signal_sets().items()}
    scorers = {"effnet": effnet_scores, **{f"verify {label}": (lambda t, s=spec: frame_scores(t, s))
                                           for label, spec in specs.items()}}
    dev_names = [Path(p).name for p in train]
    dev_labels = [split_labels(fs, "train") for fs in train_sets]
    eval_labels = {name: split_labels(fs, "val" if name in dev_names else None) for name, fs in eval_sets.items()}
    clusters = {name: instance_clusters(fs.episodes) for name, fs in eval_sets.items()}
    for name, score_of in scorers.items():
        dev = pd.concat([scored(labels, score_of(tables[set_name])).assign(  # variants share ids
            frame_id=lambda t, i=i: f"{i}:" + t.frame_id, episode_id=lambda t, i=i: f"{i}:" + t.episode_id)
            for i, (set_name, labels) in enumerate(zip(dev_names, dev_labels))])
        sigmas[name] = sigma_for(dev)
        for set_name, labels in eval_labels.items():
            frames = scored(labels, score_of(tables[set_name]))
            arrays = frame_arrays(frames)
            low, high = bootstrap_ci(arrays, sigmas[name], clusters=clusters[set_name], boot=boot)["auroc_same"] \
                or (np.nan, np.nan)
            own = sigma_for(frames)  # the set's own best sigma, to see what the development sigma gives up
            at, at_own = detection_metrics(arrays, sigmas[name]), detection_metrics(arrays, own)
            ranking = ranking_metrics(arrays)
            rows.append(dict(matcher=name, set=set_name, auroc_same=ranking["auroc_same"], low=low, high=high,
                             auroc=ranking["auroc_target"], sigma=sigmas[name],
                             tm=at["tm_pct"], cm=at["cm_pct"], match=at["match_pct"],
                             first_precision=at["first_match_precision"], own_sigma=own,
                             own_cm=at_own["cm_pct"], own_first_precision=at_own["first_match_precision"]))
    paired = {}
    for set_name, labels in eval_labels.items():
        a = scored(labels, effnet_scores(tables[set_name]))
        b = scored(labels, frame_scores(tables[set_name], specs["default"]))
        diff = paired_comparison(a, b, sigmas["effnet"], sigmas["verify default"], names=("effnet", "verify"),
                                 clusters=clusters[set_name], boot=boot).loc["AUROC-same"]
        paired[set_name] = dict(diff=float(diff["verify - effnet"]), low=float(diff["CI low"]),
                                high=float(diff["CI high"]))
    recall = {name: candidate_recall(tables[name], labels) for name, labels in eval_labels.items()
              if "cover" in tables[name]}
    return dict(rows=rows, sigmas=sigmas, paired=paired, specs=specs, candidate_recall=recall)


def candidate_lines(cands: pd.DataFrame, spec: dict) -> tuple[list[float], list[str]]:
    """Each candidate's probability and two lines of why: its number, probability, whether the colour gate cut it,
    and every signal the file weighs (two letters each: pr proto, ma margin, de desc, cy cycle, co color)."""
    floor = spec["gate"]["floor"]
    probabilities, lines = [], []
    for row in cands.to_dict("records"):
        probabilities.append(verdict(spec, row))
        signals = " ".join(f"{s[:2]} {row[s]:.2f}" for s in spec["coefs"])
        gated = ", colour gated" if floor and row["color"] < floor else ""
        lines.append(f"#{row['candidate']} p {probabilities[-1]:.2f}{gated}\n  {signals}")
    return probabilities, lines


def candidates_figure(fs: FrameSet, table: pd.DataFrame, spec: dict, path: str | Path, per_row: int = 6) -> Path:
    """What the verifier decided and why, as a picture: the highest-scoring look-alike frames over the lowest-scoring
    target frames, each with every candidate box numbered (white: the best; grey: the others) and, under the frame,
    each candidate's probability and signals; the objects' masks outlined in their roles' colours and the target's
    first reference in the corner."""
    import cv2
    import matplotlib.pyplot as plt

    from pin_match.evaluation.gallery import draw_frame, on_checkerboard, thumbnail

    frames = scored(frame_labels(fs), frame_scores(table, spec))
    same = frames[frames.same_visible & ~frames.target_visible].nlargest(per_row, "score")
    target = frames[frames.target_visible].nsmallest(per_row, "score")
    fig, axes = plt.subplots(2, per_row, figsize=(2.8 * per_row, 11.0), squeeze=False)
    for row, (title, chosen) in enumerate((("look-alike only, highest", same), ("target, lowest", target))):
        for ax, frame in zip(axes[row], chosen.itertuples()):
            image = draw_frame(fs, frame.frame_id)
            cands = table[table.frame_id == frame.frame_id]
            probabilities, lines = candidate_lines(cands, spec)
            best = int(np.argmax(probabilities))
            for k, cand in enumerate(cands.itertuples()):
                colour = (255, 255, 255) if k == best else (140, 140, 140)
                cv2.rectangle(image, (int(cand.x0), int(cand.y0)), (int(cand.x1) - 1, int(cand.y1) - 1), colour, 3)
                cv2.putText(image, str(cand.candidate), (int(cand.x0) + 4, int(cand.y1) - 8),
                            cv2.FONT_HERSHEY_SIMPLEX, 1.2, colour, 3)
            reference = thumbnail(on_checkerboard(fs.target(fs.episode(frame.episode_id).target_object_id).views[0]),
                                  110)
            image[:reference.shape[0], :reference.shape[1]] = reference
            ax.imshow(image)
            ax.set_title(f"{title}\n{frame.frame_id[-22:]}\np={max(probabilities):.2f}", fontsize=7)
            ax.text(0.0, -0.02, "\n".join(lines), transform=ax.transAxes, fontsize=5.5, va="top", family="monospace")
        for ax in axes[row]:
            ax.axis("off")
    fig.tight_layout()
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80, format=Path(path).suffix.lstrip(".") or "png")
    plt.close(fig)
    return Path(path)
