"""The gso source: a scan folder prepared from a work tree or a mirror of vikashplus/object_sim, checked on the way."""

from __future__ import annotations

import csv
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from pin_match.cli.main import main
from pin_match.data.sources import DataSourceError, get
from pin_match.data.sources import gso as gso_module
from pin_match.data.sources.gso import GSO_COMMIT, open_scan_tree, prepare_gso
from pin_match.data.sources.photo_folder import LookalikeError
from pin_match.data.sources.prepare import CommitError, checkout_commit
from pin_match.data.synth import SynthSize
from pin_match.data.synth.scans import PACKAGED_SCANS, load_scan

# a triangle and a quad off-centre (x 1..3, y 2..4, z 1..2): stored standing on z = 0, centred on x = y = 0
OBJ = """v 1 2 1
v 3 2 1
v 3 4 1
v 1 4 2
vt 0 0
vt 1 0
vt 1 1
vt 0 1
f 1/1 2/2 3/3 4/4
"""
needs_git = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


@pytest.fixture(autouse=True)
def no_repository_around(tmp_path, monkeypatch):
    """git never looks above tmp_path for a repository, wherever the tests run."""
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path))


def texture(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (4, 6, 3), dtype=np.uint8)


def work_tree(root: Path, scans=("A", "B"), licence: str = "Apache License\nVersion 2.0, January 2004\n") -> Path:
    """A plain folder laid out as the repository: LICENSE and google_objects/<scan>/model_0.obj + texture.png."""
    root.mkdir(parents=True)
    (root / "LICENSE").write_text(licence, encoding="utf-8")
    for k, name in enumerate(scans):
        folder = root / "google_objects" / name
        folder.mkdir(parents=True)
        (folder / "model_0.obj").write_text(OBJ, encoding="utf-8")
        assert cv2.imwrite(str(folder / "texture.png"), texture(k)[..., ::-1])
    return root


def rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if p.name.startswith("."))


UNCHECKED = f"(a copy without .git, taken to be commit {GSO_COMMIT[:7]}, unchecked)"


def test_prepare_writes_a_scan_folder_from_a_copy_without_git_and_says_its_commit_is_unchecked(tmp_path):
    tree = work_tree(tmp_path / "object_sim")
    out = prepare_gso(tree, tmp_path / "src")
    assert out == tmp_path / "src"
    table = rows(out / "scans.csv")
    assert [r["scan"] for r in table] == ["A", "B"]
    for r in table:
        name = r["scan"]
        assert r["source"] == f"github:vikashplus/object_sim:google_objects/{name} {UNCHECKED}"
        assert (r["mesh"], r["texture"]) == (f"scans/{name}.npz", f"scans/{name}.png")
        assert r["licence"].startswith("CC BY 4.0")
        scan = load_scan(out, name, r["mesh"], r["texture"])
        assert sorted(map(tuple, scan.mesh.vertices.tolist())) == [(-1.0, -1.0, 0.0), (-1.0, 1.0, 1.0),
                                                                  (1.0, -1.0, 0.0), (1.0, 1.0, 0.0)]
        assert len(scan.mesh.faces) == 2
        assert np.array_equal(scan.texture, texture(table.index(r)))
    assert (out / "families.csv").read_bytes() == (PACKAGED_SCANS / "families.csv").read_bytes()
    notice = (out / "NOTICE.md").read_text(encoding="utf-8")
    assert "CC BY 4.0" in notice and "2 scans" in notice
    assert f"from a copy without .git, taken to be commit {GSO_COMMIT} (unchecked" in notice
    for name in ("A", "B"):
        assert f"- `{name}`: github:vikashplus/object_sim:google_objects/{name} {UNCHECKED}, CC BY 4.0" in notice
    assert leftovers(tmp_path) == []
    with pytest.raises(LookalikeError, match="already exists: pass overwrite=True"):
        prepare_gso(tree, out)


def test_a_bad_obj_names_its_file_and_writes_nothing(tmp_path):
    tree = work_tree(tmp_path / "object_sim")
    (tree / "google_objects" / "B" / "model_0.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(LookalikeError, match=r"google_objects/B/model_0\.obj: .*face without texture coordinates"):
        prepare_gso(tree, tmp_path / "src")
    assert not (tmp_path / "src").exists() and leftovers(tmp_path) == []  # A was written to a stage, now gone


def test_a_missing_texture_names_its_file(tmp_path):
    tree = work_tree(tmp_path / "object_sim")
    (tree / "google_objects" / "A" / "texture.png").unlink()
    with pytest.raises(LookalikeError, match=rf"cannot read {re.escape(str(tree))}/google_objects/A/texture\.png"):
        prepare_gso(tree, tmp_path / "src")
    assert not (tmp_path / "src").exists()


def test_a_folder_that_is_not_the_repository_is_named(tmp_path):
    (tmp_path / "elsewhere").mkdir()
    with pytest.raises(LookalikeError, match=rf"^{re.escape(str(tmp_path / 'elsewhere'))} is not a checkout or mirror "
                                             r"of github:vikashplus/object_sim holding commit f84875d"):
        prepare_gso(tmp_path / "elsewhere", tmp_path / "src")
    with pytest.raises(LookalikeError, match=r"nowhere is not a checkout or mirror"):
        open_scan_tree(tmp_path / "nowhere")
    assert not (tmp_path / "src").exists()


def test_a_licence_that_is_not_apache_is_refused(tmp_path):
    tree = work_tree(tmp_path / "object_sim", licence="MIT License\n")
    with pytest.raises(LookalikeError, match=r"LICENSE is not the repository's Apache-2\.0 licence"):
        prepare_gso(tree, tmp_path / "src")
    (tree / "LICENSE").unlink()
    with pytest.raises(LookalikeError, match=rf"cannot read {re.escape(str(tree / 'LICENSE'))}"):
        open_scan_tree(tree)
    assert not (tmp_path / "src").exists()


def _git(*args: str, cwd: Path) -> str:
    done = subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@example.org", "-c", "commit.gpgsign=false",
                           "-c", "init.defaultBranch=main", *args], cwd=cwd, capture_output=True, text=True,
                          check=True)
    return done.stdout.strip()


def _committed_tree(root: Path) -> tuple[Path, str]:
    tree = work_tree(root)
    _git("init", "-q", cwd=tree)
    _git("add", ".", cwd=tree)
    _git("commit", "-q", "-m", "scans", cwd=tree)
    return tree, _git("rev-parse", "HEAD", cwd=tree)


@needs_git
def test_a_checkout_at_another_commit_is_refused(tmp_path):
    tree, head = _committed_tree(tmp_path / "object_sim")
    with pytest.raises(LookalikeError, match=rf"is checked out at {head[:7]}, not {GSO_COMMIT[:7]}: run `git -C "):
        prepare_gso(tree, tmp_path / "src")
    assert not (tmp_path / "src").exists()


@needs_git
def test_a_plain_copy_inside_another_repository_is_read_as_files(tmp_path):
    """git -C on a folder without .git reports the commit of a repository around it: that is not the copy's."""
    outer = tmp_path / "project"
    outer.mkdir()
    _git("init", "-q", cwd=outer)
    _git("commit", "-q", "--allow-empty", "-m", "x", cwd=outer)
    tree = work_tree(outer / "object_sim")
    assert open_scan_tree(tree).git_dir is None and not open_scan_tree(tree).checked
    assert [(r["scan"], r["source"].endswith(UNCHECKED)) for r in rows(prepare_gso(tree, tmp_path / "src") /
                                                                         "scans.csv")] == [("A", True), ("B", True)]


@needs_git
def test_a_git_directory_git_cannot_read_is_named_not_recorded_as_no_commit(tmp_path, monkeypatch):
    tree = work_tree(tmp_path / "object_sim")
    (tree / ".git").mkdir()  # a damaged checkout: git finds no repository there
    with pytest.raises(CommitError, match=rf"^{re.escape(str(tree))}: git cannot read the commit of "
                                          rf"{re.escape(str(tree / '.git'))}: "):
        prepare_gso(tree, tmp_path / "src")
    monkeypatch.setenv("PATH", str(tmp_path / "no_programs_here"))
    with pytest.raises(CommitError, match=r"cannot run git to read the commit of .*; install git, or prepare from a "
                                          r"copy without \.git \(recorded as commit unknown\)$"):
        checkout_commit(tree)
    assert not (tmp_path / "src").exists()


@needs_git
def test_a_mirror_holding_the_commit_reads_the_same_scans(tmp_path, monkeypatch):
    """A bare mirror is read with git show; the commit is the fake repository's, as the real one's cannot be made."""
    tree, head = _committed_tree(tmp_path / "object_sim")
    _git("clone", "-q", "--bare", str(tree), str(tmp_path / "mirror.git"), cwd=tmp_path)
    monkeypatch.setattr(gso_module, "GSO_COMMIT", head)
    scans = open_scan_tree(tmp_path / "mirror.git")
    assert scans.git_dir == tmp_path / "mirror.git" and scans.scan_names() == ["A", "B"]
    from_mirror = prepare_gso(tmp_path / "mirror.git", tmp_path / "from_mirror")
    from_tree = prepare_gso(tree, tmp_path / "from_tree")  # the work tree is at the (patched) commit: accepted
    assert (from_mirror / "scans.csv").read_text() == (from_tree / "scans.csv").read_text()
    assert f"@{head[:7]}:google_objects/A," in (from_mirror / "scans.csv").read_text()
    assert f"read from github:vikashplus/object_sim at commit {head} (folder" in (from_mirror / "NOTICE.md").read_text()
    assert (from_mirror / "NOTICE.md").read_text() == (from_tree / "NOTICE.md").read_text()
    for r in rows(from_mirror / "scans.csv"):
        a, b = load_scan(from_mirror, r["scan"], r["mesh"], r["texture"]), load_scan(from_tree, r["scan"], r["mesh"],
                                                                                    r["texture"])
        assert np.array_equal(a.mesh.vertices, b.mesh.vertices) and np.array_equal(a.texture, b.texture)
    _git("init", "-q", "--bare", str(tmp_path / "empty.git"), cwd=tmp_path)
    with pytest.raises(LookalikeError, match=r"empty\.git is not a checkout or mirror .* holding commit"):
        open_scan_tree(tmp_path / "empty.git")


def test_build_renders_the_shipped_scans_or_a_prepared_folder_as_synth_does(tmp_path, monkeypatch):
    """gso is the catalogue's one door to the generator: without --src, the default set of `pin-match synth`."""
    import pin_match.data.synth as synth

    calls = []

    def generate(out, size, *, scans=None, overwrite=False, **options):
        calls.append((out.name, size, scans, overwrite))
        return f"built {out.name}"

    monkeypatch.setattr(synth, "generate", generate)
    source = get("gso")
    assert source.prepare_inputs == ("CHECKOUT",) and source.licence.startswith("CC BY 4.0")
    assert source.build(tmp_path / "default") == "built default"
    source.build(tmp_path / "drawn", seed=3, src=tmp_path / "src", overwrite=True)
    assert main(["synth", str(tmp_path / "cli"), "--quiet"]) == 0
    assert calls == [("default", SynthSize(), None, False), ("drawn", SynthSize(seed=3), tmp_path / "src", True),
                     ("cli", SynthSize(), None, False)]
    with pytest.raises(DataSourceError, match=r"reads 1 input\(s\) \(CHECKOUT\), got 0"):
        source.prepare([], tmp_path / "src")
    assert list(tmp_path.iterdir()) == []
