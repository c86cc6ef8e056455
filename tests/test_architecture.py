"""The layered layout: imports run only downward, no cycles, caches survive moves."""

from __future__ import annotations

import ast
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# each top-level part of the code and its floor; a module may import only parts on lower floors, or its own part
LAYERS = {
    "pin_match.errors": 0,
    "pin_match.atomic": 1, "pin_match.outputs": 1,
    "pin_match.contract": 2,
    "pin_match.nn": 3, "pin_match.data": 3,
    "pin_match.matchers.common": 4, "pin_match.matchers": 4.1,  # helpers below the plug-ins that share them
    "pin_match.scoring": 5,
    # evaluation's rooms, in the order a run flows through them: the metrics core, the pages that draw it, the flows
    # that compose both; the package's face re-exports from core and flows
    "pin_match.evaluation.core": 6, "pin_match.evaluation.pages": 6.1, "pin_match.evaluation.flows": 6.2,
    "pin_match.evaluation": 6.3,
    "pin_match.training": 7, "pin_match.fitting": 7, "pin_match.pin_agent": 7,
    "pin_match.cli": 8,
}
# the package's own face: re-exports, above everything
FACE = {"pin_match", "pin_match.__main__"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[0] == "matchers":  # the plug-in folder installs as pin_match.matchers
        parts.insert(0, "pin_match")
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def part_of(module: str) -> str | None:
    best = None
    for part in LAYERS:
        if (module == part or module.startswith(part + ".")) and (best is None or len(part) > len(best)):
            best = part
    return best


def imports_of(path: Path) -> set[str]:
    package = module_name(path).rsplit(".", 1)[0] if path.name != "__init__.py" else module_name(path)
    return imports_of_file(path, package)


def imports_of_file(path: Path, package: str) -> set[str]:
    """Every module a file imports, at module level or inside functions (a lazy import is still a dependency)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base
                                                                                                  else []))
            found.add(base)
            found.update(f"{base}.{a.name}" for a in node.names)  # `from pin_match import atomic` is a module
    return {m for m in found if m.split(".")[0] == "pin_match"}


def library_files() -> list[Path]:
    return sorted([*(ROOT / "pin_match").rglob("*.py"), *(ROOT / "matchers").rglob("*.py")])


def test_every_library_module_belongs_to_a_layer():
    loose = [module_name(p) for p in library_files() if module_name(p) not in FACE and part_of(module_name(p)) is None]
    assert not loose, f"modules outside every layer (add them to a subpackage): {loose}"


def upward(me: str, targets: set[str]) -> list[str]:
    """The imports of module ``me`` that do not run downward (to its own part or a lower floor)."""
    mine = part_of(me)
    out = []
    for target in sorted(targets):
        theirs = part_of(target)
        if theirs is not None and theirs != mine and LAYERS[theirs] >= LAYERS[mine]:
            out.append(f"{me} ({mine}, floor {LAYERS[mine]}) imports {target} ({theirs}, floor {LAYERS[theirs]})")
    return out


MAX_MODULE_LINES = 400  # a module a reader holds at once (the developers' guide): past it, cut along its jobs


def test_every_module_is_under_400_lines():
    long = {path.relative_to(ROOT).as_posix(): n for folder in ("pin_match", "matchers", "benchmarks")
            for path in (ROOT / folder).rglob("*.py") if (n := len(path.read_text().splitlines())) >= MAX_MODULE_LINES}
    assert not long, f"modules of {MAX_MODULE_LINES} lines or more: {long}"


def test_imports_run_only_downward():
    found = [v for p in library_files() if module_name(p) not in FACE for v in upward(module_name(p), imports_of(p))]
    assert not found, "imports that do not run downward:\n" + "\n".join(found)


def test_the_layer_rule_reports_an_upward_import_and_allows_a_downward_one(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from pin_match.scoring.cache import cache_dir\n")
    assert upward("pin_match.contract.bad", imports_of_file(bad, "pin_match.contract"))
    assert not upward("pin_match.scoring.bad", imports_of_file(bad, "pin_match.scoring"))


def test_no_import_cycle_between_modules():
    modules = {module_name(p): p for p in library_files()}
    graph = {m: {t for t in imports_of(p) if t in modules and t != m and not modules[t].name == "__init__.py"}
             for m, p in modules.items() if m not in FACE}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                return stack[stack.index(n):] + [n]
            if n not in state and (cycle := visit(n)):
                return cycle
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (cycle := visit(m)):
            pytest.fail("import cycle: " + " -> ".join(cycle))


PLUG_INS, SHARED = "pin_match.matchers", "pin_match.matchers.common"


def plug_ins_reached(me: str, targets: set[str]) -> list[str]:
    """The imports of module ``me`` that reach a plug-in (a top-level module of matchers/) rather than the helpers
    the plug-ins share: a plug-in is reached by name, through the registry, so each one can move or go alone."""
    reached = {".".join(t.split(".")[:3]) for t in targets if t.startswith(PLUG_INS + ".")}  # the plug-in module
    return [f"{me} imports {t}" for t in sorted(reached - {SHARED})]


def test_no_plug_in_imports_another_and_fitting_imports_only_the_shared_helpers():
    plug_ins = [p for p in (ROOT / "matchers").glob("*.py") if p.name != "__init__.py"]
    checked = [*plug_ins, *(ROOT / "pin_match" / "fitting").rglob("*.py")]
    found = [v for p in sorted(checked) for v in plug_ins_reached(module_name(p), imports_of(p))]
    assert not found, "imports of a plug-in (move what is shared to matchers/common; build a matcher by name):\n" + \
        "\n".join(found)


def test_the_plug_in_rule_reports_a_lazy_plug_in_import_and_allows_the_shared_helpers(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("from pin_match.matchers.common.fitted import read_fitted_file\n\n\n"
                   "def f():\n    from pin_match.matchers import verify\n")
    assert plug_ins_reached("pin_match.fitting.bad", imports_of_file(bad, "pin_match.fitting")) == \
        ["pin_match.fitting.bad imports pin_match.matchers.verify"]
    good = tmp_path / "good.py"
    good.write_text("from pin_match.matchers.common import fitted\nfrom .common.patch import alpha_to_grid\n")
    assert not plug_ins_reached("pin_match.matchers.good", imports_of_file(good, "pin_match.matchers"))


def test_plugins_and_the_example_import_only_the_contract():
    for path in (ROOT / "examples" / "my_matcher.py", ROOT / "matchers" / "sift.py",
                 ROOT / "matchers" / "color.py"):
        found = {m for m in imports_of(path) if m.startswith("pin_match")}
        assert found and all(m == "pin_match.contract" or m.startswith("pin_match.contract.") for m in found), found


def test_import_pin_match_loads_neither_pandas_nor_torch():
    code = "import sys, pin_match; print('pandas' in sys.modules, 'torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["False", "False"]


# every built-in's id at its default config, as of the layout of 0.1.0 (effnet also at its earlier default, whose
# caches predate that layout). An id hashes name, version, config and weights, never a module path, so moving code
# keeps every cached table found. Only the composites (ieve, parts-cascade, fusion, verify) may change theirs, and only
# when their config changes shape (docs/architecture.md), and with them a matcher built on one (cohort-norm reads
# verify: verify's version 3 gave it a new id). A new matcher fails nothing here: it is reported (a skip with its id)
# until its id is added.
IDS = {"aliked-lightglue": "aliked-lightglue@b1e6f6ad0914", "clip": "clip@e7b5fe327f2d",
       "cohort-norm": "cohort-norm@e7038a329dc9",
       "clip-grad": "clip-grad@e400bb64f306", "clip-text": "clip-text@42f0bd222bcf", "color": "color@f03ae06173d4",
       "dino": "dino@650a30aaa20a", "dinov2": "dinov2@6e1ce2ae4f0f", "disk-lightglue": "disk-lightglue@1280f5648e34",
       "effnet": "effnet@518b38e32c83", "effnet[layer=blocks.3,img_size=224]": "effnet@d1649a13de4e",
       "effnet-lite1": "effnet-lite1@1a7fe5082f51", "effnet-lite2": "effnet-lite2@7e5fffff7a56",
       "effnet-parts": "effnet-parts@af0fab6637b5", "learned": "learned@2268bf1e5001",
       "lightglue": "lightglue@d3a9e763afe1", "mobilenetv2": "mobilenetv2@7ab6b37f8755", "owl": "owl@b4264d9cba9d",
       "owl-image": "owl-image@949968ed7099", "persam": "persam@6859f62f7160", "persam-f": "persam-f@cf6e564b8302",
       "sift": "sift@6515d01cf884", "superglue": "superglue@8c14bc055a54", "xfeat": "xfeat@1fb68fd8a821"}
COMPOSITES = {"ieve", "parts-cascade", "fusion", "verify"}


def _id(name: str) -> str:
    """The id of ``name`` as written in IDS: a matcher name, optionally with ``[key=value,...]`` overrides."""
    from pin_match.contract import create_matcher, parse_overrides

    base, _, cfg = name.partition("[")
    return create_matcher(base, **parse_overrides(cfg.rstrip("]").split(",") if cfg else [])).id


@pytest.mark.parametrize("name", sorted(IDS))
def test_matcher_ids_do_not_change_when_code_moves(name):
    assert _id(name) == IDS[name]


def _built_ins() -> list[str]:
    from pin_match.contract.registry import BUILTIN_PACKAGE, get_matcher_class, list_matchers

    return [n for n in list_matchers() if get_matcher_class(n).__module__.startswith(f"{BUILTIN_PACKAGE}.")]


def test_each_plug_in_module_registers_a_matcher_and_no_helper_does():
    """matchers/ at a glance: one module per algorithm at the top, the helpers they share in matchers/common."""
    from pin_match.contract.registry import BUILTIN_PACKAGE, get_matcher_class

    registering = {get_matcher_class(n).__module__ for n in _built_ins()}
    top = {f"{BUILTIN_PACKAGE}.{p.stem}" for p in (ROOT / "matchers").glob("*.py") if p.name != "__init__.py"}
    assert registering == top, (f"top-level modules that register nothing (move them to matchers/common): "
                                f"{sorted(top - registering)}; modules elsewhere that register: "
                                f"{sorted(registering - top)}")


def test_a_built_in_without_a_held_id_is_reported_not_failed():
    """Every name IDS holds is still a built-in; one it does not hold yet is named with the line to add."""
    built_ins = _built_ins()
    held = {n.partition("[")[0] for n in IDS}
    assert not held - set(built_ins), f"IDS holds names no built-in registers: {sorted(held - set(built_ins))}"
    new = [n for n in built_ins if n not in held | COMPOSITES]
    if new:
        pytest.skip("; ".join(f"matcher {n!r} is not in IDS: add its id, {n!r}: {_id(n)!r}, to "
                              f"tests/test_architecture.py's IDS" for n in new))


def test_a_table_cached_under_the_old_layout_is_found(tmp_path, tiny_frameset):
    """A cache folder written before the move (by its id) is what `tune --matcher` finds now."""
    import pandas as pd

    from pin_match.scoring.cache import find_score_table
    from pin_match.scoring.schema import COLUMNS
    from pin_match.scoring.table import ScoreTable

    folder = tmp_path / IDS["color"] / tiny_frameset.fingerprint  # the old cache_dir rule
    frames = tiny_frameset.frames[["frame_id", "episode_id", "step", "split"]].copy()
    frames["score"] = 0.5
    for c in ("crop_scores", "points_x", "points_y", "point_scores"):
        frames[c] = [[] for _ in range(len(frames))]
    frames["view"] = -1
    ScoreTable(frames[COLUMNS], dict(matcher="color", matcher_id=IDS["color"])).write(
        folder / "scores_all.parquet")
    assert find_score_table(tmp_path, tiny_frameset, "color") == folder / "scores_all.parquet"
    assert len(pd.read_parquet(folder / "scores_all.parquet")) == len(frames)


def test_a_built_wheel_ships_the_paper_thresholds_and_every_subpackage(tmp_path):
    import shutil

    source = tmp_path / "source"  # a copy, so the build leaves nothing in the checkout
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(".git", "build", "dist", "pin_match_runs", "*.egg-info",
                                                                "__pycache__", ".*_cache", "notebooks"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                    str(tmp_path), str(source)], check=True, capture_output=True)
    (wheel,) = tmp_path.glob("pin_match-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "pin_match/evaluation/core/paper_thresholds.json" in names
    for init in (ROOT / "pin_match").rglob("__init__.py"):
        package = init.parent.relative_to(ROOT)
        assert init.relative_to(ROOT).as_posix() in names, f"add {package} to pyproject's packages"
    for init in (ROOT / "matchers").rglob("__init__.py"):
        assert f"pin_match/{init.relative_to(ROOT).as_posix()}" in names, f"add {init.parent} to pyproject's packages"
    assert not any(n.startswith(("matchers/", "examples/")) or n.endswith("my_matcher.py") for n in names)
    assert {"pin_match/data/sources/lookalike_src/photos.csv", "pin_match/data/sources/lookalike_src/NOTICE.md",
            "pin_match/matchers/fusion_lookalike.json", "pin_match/matchers/verify_myvlm.json",
            "pin_match/data/sources/myvlm_boxes.csv"} <= names  # real sets build, the carried fits load
    assert sum(n.startswith("pin_match/data/sources/lookalike_src/photos/") for n in names) == 59
