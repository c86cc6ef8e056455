"""``index.html`` of a bench or demo folder: per frame-set a plain headline, the paired comparison and pictures,
then the table, then a link to every report and comparison page.

The headline is the question a PIN agent asks of its detector: in how many episodes was the
first frame it matched the target (``first_match_success``, with its bootstrap interval)? The
pictures answer it by eye: per val episode the target's references, then each matcher's first
frame above its sigma, drawn with the ground-truth outlines and the matcher's points.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from markupsafe import Markup

from pin_match.evaluation.core.analysis import BenchRun
from pin_match.evaluation.core.labels import CM
from pin_match.evaluation.core.layout import BenchLayout
from pin_match.evaluation.core.navigation import episodes_at, metrics_of
from pin_match.evaluation.core.sizes import BAND_EDGES
from pin_match.evaluation.core.stop import ApproachVerify, StopPolicy
from pin_match.evaluation.flows.bench import Bench
from pin_match.evaluation.flows.compare import Comparison
from pin_match.evaluation.pages import html
from pin_match.evaluation.pages.gallery import ROLE_NAMES, first_matches, frame_roles
from pin_match.evaluation.pages.pictures import legend, reference_images, scored_frame_image

EPISODES_SHOWN = 6
# what the point nearest an agent's goal landed on (``navigation.Placements.place``), as the page says it: a frame
# that shows a look-alike may have fired on the floor beside it
LANDED = {"target": "the target", "same_category": "a look-alike", "other": "another object",
          "background": "nothing annotated"}
PICTURE_SIZE = 200
LARGE_PX = BAND_EDGES[1]  # pixels: a target shown this large is one a matcher can be asked to recognise
INDEX_ASSETS = "index_files"
# the closed loop a set whose houses can be staged again shows beside PIN's first match, at the same sigma: at each
# firing the agent walks up to the candidate, looks again from within 1 m and commits only if that look reaches sigma
CLOSED_LOOP = ApproachVerify()


@dataclass(frozen=True)
class SetResults:
    """One frame-set's part of the page: what it is, its bench, and its matchers compared with the first."""

    name: str
    caption: str
    bench: Bench
    comparisons: Sequence[Comparison] = ()
    sigma_note: str = ""  # where the demo's sigmas came from, and why where the shipped ones did not apply


def first_match_line(result: dict) -> str:
    """'verify: the target in 14 of 20 episodes (70.0 %, 95 % CI 50.0-85.0 %)' from a report."""
    m, ci = result["metrics"], result["ci95"].get("first_match_success")
    share = m.get("first_match_success")
    interval = f", 95 % CI {ci[0]:.1f}-{ci[1]:.1f} %" if ci else ""
    pct = "n/a" if share is None else f"{share:.1f} %"
    return f"{result['matcher']}: the target in {m['n_first_tm']} of {m['n_episodes']} episodes ({pct}{interval})"


def headline(results: Sequence[dict]) -> str:
    """Which matcher's first match was the target in the most val episodes, then the others in that order."""
    ranked = sorted(results, key=lambda r: (-(r["metrics"].get("first_match_success") or 0.0), r["matcher"]))
    sources = sorted({r["sigma_source"] for r in ranked})
    lines = "; ".join(first_match_line(r) for r in ranked)
    return f"First match is the target (the frame where PIN's agent would stop): {lines}. Sigma: {', '.join(sources)}."


def navigation_line(results: Sequence[dict]) -> str | None:
    """SR and CE of each matcher (the navigation estimate, with intervals), or None without geometry."""
    if not all("sr" in r["metrics"] for r in results):
        return None

    def said(r: dict, key: str) -> str:
        ci = r["ci95"].get(key)
        return f"{r['metrics'][key]:.1f} %" + (f" ({ci[0]:.1f}-{ci[1]:.1f})" if ci else "")

    parts = [f"{r['matcher']} SR {said(r, 'sr')}, CE {said(r, 'ce')}" for r in results]
    return ("What the agent would do (estimated from the recorded walks: where the stop policy commits to a match "
            "placed with depth, the agent walks toward it and stands on the floor nearest it; success: standing "
            "within 1 m of the target, CE within 1 m of a look-alike): "
            + "; ".join(parts) + ".")


def comparison_lines(c: Comparison) -> list[str]:
    """The paired differences that decide the ranking, each with its interval, and McNemar's count."""
    diff = f"{c.names[1]} - {c.names[0]}"
    a, b = (name.split("@")[0] for name in c.names)  # the ids are on the compare page
    parts = []
    for metric in ("FM-prec", "AUROC-same", "AUROC"):
        row = c.paired.loc[metric]
        if not np.isfinite(row[diff]):  # FM-prec where one of the two matched no episode
            parts.append(f"{metric} n/a (one of them matched no episode)")
            continue
        scale = "" if metric.startswith("AUROC") else " points"
        if row["CI low"] == row["CI high"]:  # every resample gives the same difference: no interval to show
            parts.append(f"{metric} {row[diff]:+.3g}{scale} (the same in every resample: too few episodes to tell)")
            continue
        parts.append(f"{metric} {row[diff]:+.3g}{scale} (95 % CI {row['CI low']:+.3g} to {row['CI high']:+.3g})")
    t = c.test
    return [f"{b} minus {a}: " + "; ".join(parts) + ".",
            f"The first match was the target for {a} only in {t['only_a']} episodes, for {b} only in {t['only_b']}, "
            f"for both in {t['both']} (McNemar p = {t['p_value']:.3g})."]


def stop_line(walk) -> str:
    """Where the agent stopped (the navigation estimate), in a few words."""
    if walk.outcome == "not found":
        never = "never stops" if pd.isna(walk.fired_step) else "is still looking when the walk ends"
        return f"the agent {never}: {walk.d2g:.1f} m from the target at the walk's end"
    on = f" (its goal point on: {LANDED[walk.landed_on]})" if walk.landed_on in LANDED else ""
    return f"the agent stops at step {walk.stop_step:.0f}{on}: {walk.outcome}, {walk.d2g:.2f} m from the target"


def walks_under(run: BenchRun, matcher: str, policy: StopPolicy) -> pd.DataFrame:
    """Each val episode's walk under ``policy`` at the matcher's sigma (``navigation.episodes_at``; an approach-verify
    policy's walk-ups rendered and scored on demand), indexed by episode id."""
    walks = episodes_at(run.context.placements(run.tables[matcher], "val"), run.sigmas[matcher], policy)
    return walks.set_index("episode_id", drop=False)


def stops(run: BenchRun, matcher: str) -> pd.DataFrame:
    """Each val episode's stop under the stop policy the matcher was reported with; none without the frame-set's
    geometry."""
    if run.frameset.navigation_missing is not None:
        return pd.DataFrame()
    return walks_under(run, matcher, StopPolicy.parse(run.reports[matcher].get("policy", "1-of-1")))


def closed_loop(run: BenchRun, matcher: str) -> pd.DataFrame:
    """Each val episode under ``CLOSED_LOOP``; none where the set's houses cannot be staged again (real photos, a
    recording) or it has no geometry."""
    if run.frameset.navigation_missing is not None or run.context.walk_ups is None:
        return pd.DataFrame()
    return walks_under(run, matcher, CLOSED_LOOP)


def closed_loop_line(loops: dict[str, pd.DataFrame], first: dict[str, pd.DataFrame]) -> str | None:
    """SR and CE under the closed loop beside the stop rule the set was reported with, and what the walk-ups turned
    down, per matcher; None where no matcher has closed-loop walks."""
    if all(walks.empty for walks in loops.values()):
        return None
    parts = []
    for m, walks in loops.items():
        turned = f"candidates turned down: {int(walks.rejected.sum())} (look-alikes " \
                 f"{int(walks.rejected_lookalike.sum())}, the target {int(walks.rejected_target.sum())})"
        loop, before = metrics_of(walks), metrics_of(first[m])
        parts.append(f"{m} SR {loop['sr']:.1f} %, CE {loop['ce']:.1f} % (the stop rule above: SR {before['sr']:.1f} "
                     f"%, CE {before['ce']:.1f} %), {turned}")
    return (f"The closed loop ({CLOSED_LOOP}, the same sigma: at each firing the agent walks up to the candidate, "
            "looks again from within 1 m and commits only where that look reaches sigma, else walks on; every step "
            "of the detours counted): " + "; ".join(parts) + ".")


def closed_loop_caption(walk) -> str:
    """What the closed loop did in one episode, in a few words."""
    looks = [text.split(":") for text in walk.rejections.split("; ")] if walk.rejected else []
    turned = ", ".join(f"{LANDED.get(role, role)} at step {step} (close look {close})" for step, role, close in looks)
    return f"closed loop: turned down {turned or 'nothing'}; {stop_line(walk)}"


def first_match_roles(run: BenchRun) -> dict[str, pd.DataFrame]:
    """Per matcher, each val episode's first frame above its sigma with the role it shows, by episode id (an
    episode where it never fired is absent)."""
    firsts = {}
    for m in run.matchers:
        first = first_matches(run.scored(m, "val"), run.sigmas[m])
        firsts[m] = first.assign(role=frame_roles(first)).set_index("episode_id")
    return firsts


def target_sight(labels: pd.DataFrame) -> pd.DataFrame:
    """Per episode of ``labels`` (the frame labels), how many of its walk's frames show its target (walk-up views
    left out) and the most pixels it covered in one: whether the walk gave a matcher anything to find."""
    walk = labels[~labels.approach].groupby("episode_id")
    return pd.DataFrame({"frames": walk.target_visible.sum(), "largest": walk.target_pixels.max()})


def sight_line(labels: pd.DataFrame) -> str:
    """In how many val episodes the walk shows the target at all, and large (``target_sight``): an episode whose
    walk never shows its target is lost whatever the matcher, which bounds every SR on the page."""
    sight = target_sight(labels[labels.split == "val"])
    shown, large = int((sight.frames > 0).sum()), int((sight.largest >= LARGE_PX).sum())
    return (f"The walks show the target in {shown} of {len(sight)} val episodes, at {LARGE_PX:,} px or more in "
            f"{large}: where a walk never shows it, no matcher can find it.")


def roles_line(firsts: dict[str, pd.DataFrame], n_val: int) -> str:
    """'What each first match showed, over the 6 val episodes: verify: nothing 3, never fired 3; ...': why a
    matcher misses the target, at a glance (a look-alike, another object, an empty wall, or silence)."""
    parts = []
    for m, first in firsts.items():
        counts = first.role.value_counts()
        said = [f"{role} {int(counts[role])}" for role in ROLE_NAMES if role in counts.index]
        if len(first) < n_val:
            said.append(f"never fired {n_val - len(first)}")
        parts.append(f"{m}: {', '.join(said)}")
    return f"What each first match showed, over the {n_val} val episodes: " + "; ".join(parts) + "."


def episode_pictures(s: SetResults, assets: html.Assets, firsts: dict[str, pd.DataFrame],
                     walks: dict[str, pd.DataFrame], loops: dict[str, pd.DataFrame],
                     episodes: int = EPISODES_SHOWN) -> list[Markup]:
    """One row per val episode, one column per matcher: the target's references, then each matcher's first frame
    above its sigma (``firsts``), where the agent would stop (``walks``, where the frame-set has geometry) and what
    the closed loop did (``loops``, where its houses can be staged again)."""
    run = s.bench.run
    val = run.frameset.episodes[run.frameset.episodes.split == "val"].set_index("episode_id", drop=False)
    val = val.loc[shown_episodes(list(val.index), [firsts[m].role for m in run.matchers], episodes)]
    sights = target_sight(run.labels)
    rows = []
    for _, ep in val.iterrows():
        target = run.frameset.target(ep.target_object_id)
        frames, largest = sights.loc[ep.episode_id]
        sight = f"in view in {frames} walk frames, {largest:,} px at most" if frames else "never in view on the walk"
        figures = [html.figure(reference_images(assets, target), [f"episode {ep.episode_id}",
                                                                  f"target {target.object_id} ({target.category})",
                                                                  sight])]
        for m in run.matchers:
            stop = [stop_line(walks[m].loc[ep.episode_id])] if ep.episode_id in walks[m].index else []
            stop += [closed_loop_caption(loops[m].loc[ep.episode_id])] if ep.episode_id in loops[m].index else []
            if ep.episode_id not in firsts[m].index:
                figures.append(html.figure([], [f"{m}: no frame above sigma {run.sigmas[m]:g}", *stop], "miss"))
                continue
            f = firsts[m].loc[ep.episode_id]
            image = scored_frame_image(assets, run.frameset, run.tables[m], f.frame_id, run.sigmas[m],
                                       box=PICTURE_SIZE)
            figures.append(html.figure([image], [f"{m}: first match at step {f.step}", f"shows: {f.role}",
                                                 f"score {f.score:.3g} (sigma {run.sigmas[m]:g})", *stop],
                                       "hit" if f.role == "target" else "miss"))
        rows.append(figures)
    return [html.figure_table(["target", *run.matchers], rows)]


def shown_episodes(episode_ids: Sequence[str], first_roles: Sequence[pd.Series], episodes: int) -> list[str]:
    """The val episodes the page draws: first those where some matcher's first match is a look-alike (the paper's
    open problem, shown by eye), then the others, each group in id order; ``first_roles``: per matcher, the role
    its first match shows (``gallery.frame_roles``), by episode id."""
    confused = {e for roles in first_roles for e, role in roles.items() if role == ROLE_NAMES[CM]}
    ordered = sorted(episode_ids, key=lambda e: (e not in confused, e))
    return ordered[:episodes]


def set_section(s: SetResults, assets: html.Assets) -> list[Markup]:
    n_val = int((s.bench.run.frameset.episodes.split == "val").sum())
    shown = min(n_val, EPISODES_SHOWN)
    firsts = first_match_roles(s.bench.run)
    parts = [html.heading(s.name), html.paragraph(s.caption, "note"), html.paragraph(headline(s.bench.results)),
             html.paragraph(sight_line(s.bench.run.labels)), html.paragraph(roles_line(firsts, n_val))]
    walks = {m: stops(s.bench.run, m) for m in s.bench.run.matchers}
    loops = {m: closed_loop(s.bench.run, m) for m in s.bench.run.matchers}
    parts += [html.paragraph(line) for line in (navigation_line(s.bench.results), closed_loop_line(loops, walks))
              if line]
    if s.comparisons:
        parts += [html.heading("Paired comparison", 3),
                  *(html.paragraph(line) for c in s.comparisons for line in comparison_lines(c))]
    parts += [html.heading("Each matcher's first match", 3),
              html.paragraph(f"{shown} of {n_val} val episodes (those where a matcher's first match was a "
                             "look-alike come first): the target's references, then where each matcher first fired "
                             "(green border: the target; red: anything else, or nothing).", "note"),
              *episode_pictures(s, assets, firsts, walks, loops),
              html.heading("All metrics", 3), html.table(s.bench.joint, s.bench.caption)]
    return parts


def write_index(out: str | Path | BenchLayout, sets: Sequence[SetResults]) -> Path:
    """Write ``index.html`` (images in ``index_files/``): each set's story, then links to every page under it."""
    layout = out if isinstance(out, BenchLayout) else BenchLayout(Path(out))
    root = layout.root
    assets = html.Assets(layout.index, INDEX_ASSETS)
    parts: list[Markup] = [legend()]
    pages = []
    for s in sets:
        parts += set_section(s, assets)
        pages += [s.bench.run.layout.report_page(m) for m in s.bench.run.matchers]
        pages += [c.folder.page for c in s.comparisons]
    links = [html.link(html.relative(p, root), html.relative(p.parent, root)) for p in pages]
    note = f"{len(pages)} pages: a report per matcher and frame-set with its galleries, then the paired comparisons."
    parts += [html.heading("Reports and comparisons"), html.paragraph(note, "note"), html.bullets(links)]
    return html.write_page(layout.index, f"pin_match results in {root}", parts)
