"""Google Scanned Objects: real household products scanned as textured meshes (CC BY 4.0), in look-alike families.

Google Research's scans (Downs et al., ICRA 2022) are real products, many in families of real
look-alikes: the same box with another print, the same pot in another colour, a set of white
porcelain in different shapes. 400 of them sit in the public repository vikashplus/object_sim at
commit ``f84875d`` (folder ``google_objects/``, removed from the repository's head later). ``pin-match
data prepare gso CHECKOUT --out SRC`` reads them from a checkout or a bare mirror of that
repository, at that commit, or from a copy without ``.git`` (GitHub's archive of that commit: its
commit cannot be checked, and scans.csv and NOTICE.md say so), and writes a scan folder
(``pin_match.data.synth.scans.ScanFolder``) through ``prepare.write_source_folder``: every scan as
a compact mesh and its texture, ``scans.csv`` with each scan's source and licence, the look-alike
families shipped with pin_match (``families.csv``, edit it to draw others) and a NOTICE.md that
attributes every scan.

This is the catalogue's one door to the synthetic generator (``pin_match.data.synth``):
``pin-match data build gso OUT`` renders the default set from the 96 scans shipped inside
pin_match (written by the same function), ``--src SRC`` a prepared folder's families instead.
``pin-match synth`` is the same generator with its sizes as options (docs/synthetic.md).
"""

from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.data.sources.catalogue import SRC_OPTIONAL, DataSource, register
from pin_match.data.sources.photo_folder import LookalikeError
from pin_match.data.sources.prepare import IndexTable, checkout_commit, write_source_folder
from pin_match.data.synth.scans import PACKAGED_SCANS, SCAN_COLUMNS, ScanError, read_obj, standing, write_scan

GSO_REPO = "github:vikashplus/object_sim"
GSO_COMMIT = "f84875da42fd759fe16c1ed111db44e8d19f9001"
GSO_FOLDER = "google_objects"
GSO_LICENCE = "CC BY 4.0 (Google Scanned Objects, Google Research)"
GSO_CITATION = ("L. Downs, A. Francis, N. Koenig, B. Kinman, R. Hickman, K. Reymann, T. B. McHugh, V. Vanhoucke: "
                "Google Scanned Objects: A High-Quality Dataset of 3D Scanned Household Items, ICRA 2022. "
                "Licence: https://creativecommons.org/licenses/by/4.0/")


@dataclass(frozen=True)
class ScanTree:
    """The repository's files at ``GSO_COMMIT``: a work tree checked out there (or a copy of one without ``.git``,
    unchecked), or a git directory read with git."""

    root: Path
    git_dir: Path | None  # None: read the work tree's files
    checked: bool = True  # False: a copy without .git, taken to be at GSO_COMMIT with nothing to check it against

    def source(self, where: str) -> str:
        """What scans.csv records as the source of the scan in folder ``where``."""
        if self.checked:
            return f"{GSO_REPO}@{GSO_COMMIT[:7]}:{where}"
        return f"{GSO_REPO}:{where} (a copy without .git, taken to be commit {GSO_COMMIT[:7]}, unchecked)"

    def read(self, path: str) -> bytes:
        if self.git_dir is None:
            try:
                return (self.root / path).read_bytes()
            except OSError as exc:
                raise LookalikeError(f"cannot read {self.root / path}: {exc.strerror or exc}") from None
        done = subprocess.run(["git", "--git-dir", str(self.git_dir), "show", f"{GSO_COMMIT}:{path}"],
                              capture_output=True, timeout=120)
        if done.returncode:
            raise LookalikeError(f"{self.git_dir}: cannot read {path} at {GSO_COMMIT[:7]}: "
                                 f"{done.stderr.decode(errors='replace').strip()}")
        return done.stdout

    def scan_names(self) -> list[str]:
        """Every folder of ``google_objects/`` that holds a textured model."""
        if self.git_dir is None:
            folder = self.root / GSO_FOLDER
            return sorted(p.name for p in folder.iterdir() if (p / "model_0.obj").is_file())
        done = subprocess.run(["git", "--git-dir", str(self.git_dir), "ls-tree", "-r", "-z", "--name-only",
                               GSO_COMMIT, f"{GSO_FOLDER}/"], capture_output=True, timeout=120)
        files = done.stdout.decode("utf-8").split("\0")
        return sorted(f.split("/")[1] for f in files if f.endswith("/model_0.obj"))


def open_scan_tree(root: str | Path) -> ScanTree:
    """``root`` as the repository at ``GSO_COMMIT``: a checkout of that commit, or any clone or mirror holding it."""
    root = Path(root)
    if (root / GSO_FOLDER).is_dir():
        commit = checkout_commit(root)  # None: a copy without .git
        if commit is not None and commit != GSO_COMMIT:
            raise LookalikeError(f"{root} is checked out at {commit[:7]}, not {GSO_COMMIT[:7]}: run "
                                 f"`git -C {root} checkout {GSO_COMMIT[:7]}` (the scans left the repository later)")
        tree = ScanTree(root, None, checked=commit is not None)
    else:
        git_dir = next((d for d in (root / ".git", root) if (d / "HEAD").is_file()), None)
        found = git_dir is not None and subprocess.run(
            ["git", "--git-dir", str(git_dir), "cat-file", "-e", f"{GSO_COMMIT}:{GSO_FOLDER}"],
            capture_output=True, timeout=60).returncode == 0
        if not found:
            raise LookalikeError(f"{root} is not a checkout or mirror of {GSO_REPO} holding commit "
                                 f"{GSO_COMMIT[:7]} (its {GSO_FOLDER}/ folder)")
        tree = ScanTree(root, git_dir)
    if b"Apache License" not in tree.read("LICENSE"):
        raise LookalikeError(f"{root}: LICENSE is not the repository's Apache-2.0 licence: is this {GSO_REPO}?")
    return tree


def write_scans(tree: ScanTree, names: list[str], stage: Path) -> list[dict[str, str]]:
    """Each named scan as a compact mesh and its texture under ``stage/scans/``; their ``scans.csv`` rows."""
    rows = []
    for name in names:
        where = f"{GSO_FOLDER}/{name}"
        try:
            mesh = standing(read_obj(tree.read(f"{where}/model_0.obj").decode("utf-8"), where))
        except (ScanError, UnicodeDecodeError) as exc:
            raise LookalikeError(f"{tree.root}: {where}/model_0.obj: {exc}") from None
        mesh_file, texture_file = write_scan(stage / "scans" / name, mesh, tree.read(f"{where}/texture.png"))
        rows.append(dict(scan=name, mesh=f"scans/{mesh_file}", texture=f"scans/{texture_file}",
                         source=tree.source(where), licence=GSO_LICENCE))
    return rows


def notice(tree: ScanTree, rows: list[dict[str, str]]) -> str:
    """NOTICE.md of a scan folder: the attribution CC BY asks for, one line per scan."""
    lines = "\n".join(f"- `{r['scan']}`: {r['source']}, {r['licence']}" for r in rows)
    read_from = f"at commit {GSO_COMMIT}" if tree.checked else \
        f"from a copy without .git, taken to be commit {GSO_COMMIT} (unchecked: the copy has no history to check)"
    return f"""# Sources and licences of these scans

Every mesh and texture here is a scan of the Google Scanned Objects collection by Google Research,
licensed under CC BY 4.0; pin_match converted each OBJ to a compact mesh (same vertices, triangles
and UVs, moved to stand on z = 0) and kept its texture as published. Cite:
{GSO_CITATION}

They were read from {GSO_REPO} {read_from} (folder `{GSO_FOLDER}/`; that repository's own
code is Apache-2.0, the scans are Google's). {len(rows)} scans:

{lines}
"""


def copy_families(stage: Path) -> list[dict[str, str]]:
    """The look-alike families shipped with pin_match, as a scan folder's ``families.csv``."""
    atomic.write_bytes(stage / "families.csv", (PACKAGED_SCANS / "families.csv").read_bytes())
    return []


SCAN_INDEX = IndexTable("scans.csv", SCAN_COLUMNS)


def write_scan_folder(tree: ScanTree, out: str | Path, names: list[str] | None = None, *,
                      overwrite: bool = False) -> Path:
    """Write a scan folder at ``out`` holding ``names`` (default: every scan), the shipped families and a NOTICE."""
    names = names if names is not None else tree.scan_names()
    return write_source_folder(out, lambda stage: write_scans(tree, names, stage),
                               lambda rows, _families: notice(tree, rows), index=SCAN_INDEX,
                               write_rest=copy_families, overwrite=overwrite)


def prepare_gso(checkout: Path, out: Path, *, overwrite: bool = False) -> Path:
    """``pin-match data prepare gso CHECKOUT --out SRC``: every scan of the repository into a scan folder."""
    return write_scan_folder(open_scan_tree(checkout), out, overwrite=overwrite)


def _make(out: Path, *, variant: str, seed: int, src: Path | None, overwrite: bool) -> FrameSet:
    """The synthetic generator at its default sizes: the scans shipped with pin_match, or those of ``src``."""
    from pin_match.data.synth import SynthSize, generate  # pybullet loads only when a set is rendered

    return generate(out, SynthSize(seed=seed), scans=src, overwrite=overwrite)


SOURCE = register(DataSource(
    name="gso",
    summary="Google Scanned Objects in look-alike families, rendered on the CPU along PIN walks: without --src "
            "the embedded default set (the 96 scans shipped with pin_match, as `pin-match synth` with its default "
            "sizes), with --src a prepared folder's families drawn from all 400 (docs/synthetic.md)",
    licence=f"{GSO_LICENCE}; each scan named in the frame-set's objects.csv and in the scan folder's NOTICE.md",
    variants=("default",), make=_make, src=SRC_OPTIONAL, prepare_inputs=("CHECKOUT",), make_source=prepare_gso))
