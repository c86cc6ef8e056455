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

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pin_match import atomic, outputs
from pin_match.contract.matcher import Matcher
from pin_match.contract.registry import create_matcher
from pin_match.data.frameset import FrameSet
from pin_match.evaluation.core.evaluator import EvalContext
from pin_match.evaluation.core.intervals import instance_clusters
from pin_match.evaluation.core.labels import scored_frames
from pin_match.evaluation.core.metrics import DEFAULT_BOOT, Bootstrap
from pin_match.evaluation.core.paired import paired_comparison
from pin_match.evaluation.core.tuning import sigma_for
from pin_match.evaluation.flows.carry import carried, pooled
from pin_match.fitting.logistic import FitError
from pin_match.fitting.verifier import candidate_table, fit_spec, frame_scores
from pin_match.matchers.common.verifier_file import DEFAULT_SIGNALS, SIGNALS, verdict
from pin_match.scoring.options import DEFAULT_RUN, RunOptions
from pin_match.scoring.table import ScoreTable


def signal_sets(signals: Sequence[str] = SIGNALS) -> dict[str, dict]:
    """The ablation's rows as ``verify`` overrides, all read from one table of ``signals``: the default (with and
    without the colour gate) when ``signals`` hold it, all of them, each alone, each left out of all (a set without
    ``color`` has no gate)."""
    sets = {"default": DEFAULT_SIGNALS, "all": tuple(signals)} if set(DEFAULT_SIGNALS) <= set(signals) \
        else {"all": tuple(signals)}
    sets.update({f"{s} alone": (s,) for s in signals})
    if len(signals) > 1:
        sets.update({f"without {s}": tuple(x for x in signals if x != s) for s in signals})
    rows = {label: dict(signals=s) if "color" in s else dict(signals=s, color_gate=0.0) for label, s in sets.items()}
    if "default" in sets:
        rows["default, no gate"] = dict(signals=DEFAULT_SIGNALS, color_gate=0.0)
    return rows


def candidate_recall(table: pd.DataFrame, labels: pd.DataFrame, share: float = 0.5) -> float:
    """Share of the target frames where some candidate box holds at least ``share`` of the target's visible pixels:
    what no signal can rescue when it fails."""
    target_frames = set(labels.frame_id[labels.target_visible])
    best = table[table.frame_id.isin(target_frames)].groupby("frame_id").cover.max()
    return float((best.reindex(sorted(target_frames)).fillna(0.0) >= share).mean()) if target_frames else float("nan")


def scored(labels: pd.DataFrame, scores: pd.DataFrame, name: str) -> pd.DataFrame:
    """The labelled frames of ``scores``' frames with their score (``labels.scored_frames``' checks)."""
    return scored_frames(labels, ScoreTable(scores, {"matcher_id": name}))


def effnet_scores(table: pd.DataFrame) -> pd.DataFrame:
    """The default ``effnet``'s frame scores: the locate peak of each frame's first candidate."""
    first = table[table.candidate == 0]
    return pd.DataFrame({"frame_id": first.frame_id.to_numpy(), "score": first.proto.to_numpy()})


@dataclass(frozen=True)
class Sets:
    """The report's frame-sets, keyed by the path as given (two folders of one name stay apart): the development
    sets' train splits, the evaluation sets' (PATH:SPLIT; a development set without one: its val split), each
    set's labels built once and each split's candidate table."""

    train: dict[str, tuple[FrameSet, pd.DataFrame, pd.DataFrame]]
    evals: dict[str, tuple[FrameSet, pd.DataFrame, pd.DataFrame]]

    @classmethod
    def load(cls, train: Sequence[str], evals: Sequence[str], base: Matcher, features: str | Path,
             run: RunOptions) -> Sets:
        contexts: dict[str, EvalContext] = {}

        def one(path: str, split: str | None) -> tuple[FrameSet, pd.DataFrame, pd.DataFrame]:
            ctx = contexts.setdefault(path, EvalContext(FrameSet.load(path)))
            fs = ctx.fs.split(split)
            return fs, ctx.split_labels(split), candidate_table(fs, base, out=features, run=run)

        if not train:
            raise FitError("verifier report: no development frame-set to fit and tune on (--train)")
        dev = {str(p): one(str(p), "train") for p in train}
        evaluated = {}
        for item in evals:
            path, _, split = str(item).partition(":")
            evaluated[str(item)] = one(path, split or ("val" if path in dev else None))
        return cls(dev, evaluated)


def report(train: Sequence[str], evals: Sequence[str], features: str | Path = outputs.FEATURES,
           boot: Bootstrap = DEFAULT_BOOT, signals: Sequence[str] = DEFAULT_SIGNALS,
           run: RunOptions = DEFAULT_RUN) -> dict:
    """Every signal set of ``signals`` and ``effnet`` on every evaluation set, fitted and tuned on the development
    sets' train splits; the candidate signals are computed once (``candidate_table``) and every row reads them.
    ``sets`` in the result are the frame-sets, labels and candidate tables read (``Sets``)."""
    base = create_matcher("verify", **signal_sets(signals)["all"])
    sets = Sets.load(train, evals, base, features, run)
    specs = {label: fit_spec(create_matcher("verify", **overrides), list(sets.train.values()), "train", 1.0)
             for label, overrides in signal_sets(signals).items()}
    scorers = {"effnet": effnet_scores, **{f"verify {label}": (lambda t, s=spec: frame_scores(t, s))
                                           for label, spec in specs.items()}}
    clusters = {name: instance_clusters(fs.episodes) for name, (fs, _, _) in sets.evals.items()}
    rows, sigmas = [], {}
    for name, score_of in scorers.items():
        dev = [scored(labels, score_of(table), name) for _, labels, table in sets.train.values()]
        if all(d.empty for d in dev):
            raise FitError(f"verifier report: the development sets' train splits ({', '.join(sets.train)}) hold no "
                           "frame to tune sigma on")
        sigmas[name] = sigma_for(pooled(dev))
        for set_name, (_, labels, table) in sets.evals.items():
            frames = scored(labels, score_of(table), name)
            rows.append(dict(matcher=name, set=set_name, **carried(frames, sigmas[name], clusters[set_name], boot)))
    paired = {}
    default = "verify default" if "default" in specs else "verify all"
    for set_name, (_, labels, table) in sets.evals.items():
        a = scored(labels, effnet_scores(table), "effnet")
        b = scored(labels, scorers[default](table), default)
        diff = paired_comparison(a, b, sigmas["effnet"], sigmas[default], names=("effnet", "verify"),
                                 clusters=clusters[set_name], boot=boot).loc["AUROC-same"]
        paired[set_name] = dict(diff=float(diff["verify - effnet"]), low=float(diff["CI low"]),
                                high=float(diff["CI high"]))
    recall = {name: candidate_recall(table, labels) for name, (_, labels, table) in sets.evals.items()}
    return dict(rows=rows, sigmas=sigmas, paired=paired, specs=specs, candidate_recall=recall, sets=sets)


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


def candidates_figure(fs: FrameSet, labels: pd.DataFrame, table: pd.DataFrame, spec: dict, path: str | Path,
                      per_row: int = 6) -> Path:
    """What the verifier decided and why, as a picture: the highest-scoring look-alike frames over the lowest-scoring
    target frames, each with every candidate box numbered (white: the best; grey: the others) and, under the frame,
    each candidate's probability and signals; the objects' masks outlined in their roles' colours and the target's
    first reference in the corner. ``labels``: ``fs``'s frame labels, of the frames ``table`` holds."""
    import cv2
    import matplotlib.pyplot as plt

    from pin_match.evaluation.pages.gallery import draw_frame, on_checkerboard, thumbnail

    frames = scored(labels, frame_scores(table, spec), "verify")
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
