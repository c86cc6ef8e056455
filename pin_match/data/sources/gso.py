"""Google Scanned Objects: real household products scanned as textured meshes (CC BY 4.0), in look-alike families.

Google Research's scans (Downs et al., ICRA 2022) are real products, many in families of real
look-alikes: the same box with another print, the same pot in another colour, a set of white
porcelain in different shapes. 400 of them sit in the public repository vikashplus/object_sim at
commit ``f84875d`` (folder ``google_objects/``, removed from the repository's head later). ``pin-match
data prepare gso CHECKOUT --out SRC`` reads them from a checkout or a bare mirror of that
repository, at that commit, and writes a scan folder (``pin_match.data.synth.scans.ScanFolder``):
every scan as a compact mesh and its texture, ``scans.csv`` with each scan's source and licence,
the look-alike families shipped with pin_match (``families.csv``, edit it to draw others) and a
NOTICE.md that attributes every scan. ``pin-match data build gso OUT --src SRC`` renders the
synthetic generator's walks with those families; the default set (``pin-match synth``) uses the
scans shipped inside pin_match, written by the same function (docs/synthetic.md).
"""

from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path

from pin_match import atomic
from pin_match.data.frameset import FrameSet
from pin_match.data.sources.catalogue import SRC_REQUIRED, DataSource, register
from pin_match.data.sources.photo_folder import LookalikeError, write_csv
from pin_match.data.sources.prepare import checkout_commit, staged_source
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
    """The repository's files at ``GSO_COMMIT``: a work tree checked out there, or a git directory read with git."""

    root: Path
    git_dir: Path | None  # None: read the work tree's files

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
        # only a checkout's own .git: git -C on a plain copy would report the commit of a repository around it
        commit = checkout_commit(root) if (root / ".git").exists() else None
        if commit is not None and commit != GSO_COMMIT:
            raise LookalikeError(f"{root} is checked out at {commit[:7]}, not {GSO_COMMIT[:7]}: run "
                                 f"`git -C {root} checkout {GSO_COMMIT[:7]}` (the scans left the repository later)")
        tree = ScanTree(root, None)
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
                         source=f"{GSO_REPO}@{GSO_COMMIT[:7]}:{where}", licence=GSO_LICENCE))
    return rows


def notice(rows: list[dict[str, str]]) -> str:
    """NOTICE.md of a scan folder: the attribution CC BY asks for, one line per scan."""
    lines = "\n".join(f"- `{r['scan']}`: {r['source']}, {r['licence']}" for r in rows)
    return f"""# Sources and licences of these scans

Every mesh and texture here is a scan of the Google Scanned Objects collection by Google Research,
licensed under CC BY 4.0; pin_match converted each OBJ to a compact mesh (same vertices, triangles
and UVs, moved to stand on z = 0) and kept its texture as published. Cite:
{GSO_CITATION}

They were read from {GSO_REPO} at commit {GSO_COMMIT} (folder `{GSO_FOLDER}/`; that repository's own
code is Apache-2.0, the scans are Google's). {len(rows)} scans:

{lines}
"""


def write_scan_folder(tree: ScanTree, out: str | Path, names: list[str] | None = None, *,
                      overwrite: bool = False) -> Path:
    """Write a scan folder at ``out`` holding ``names`` (default: every scan), the shipped families and a NOTICE."""
    out = Path(out)
    names = names if names is not None else tree.scan_names()
    with staged_source(out, overwrite) as stage:
        rows = write_scans(tree, names, stage)
        write_csv(stage / "scans.csv", SCAN_COLUMNS, rows)
        atomic.write_bytes(stage / "families.csv", (PACKAGED_SCANS / "families.csv").read_bytes())
        atomic.write_text(stage / "NOTICE.md", notice(rows))
    return out


def prepare_gso(checkout: Path, out: Path, *, overwrite: bool = False) -> Path:
    """``pin-match data prepare gso CHECKOUT --out SRC``: every scan of the repository into a scan folder."""
    return write_scan_folder(open_scan_tree(checkout), out, overwrite=overwrite)


def _make(out: Path, *, variant: str, seed: int, src: Path | None, overwrite: bool) -> FrameSet:
    from pin_match.data.synth import SynthSize, generate  # pybullet loads only when a set is rendered

    return generate(out, SynthSize(seed=seed), scans=src, overwrite=overwrite)


SOURCE = register(DataSource(
    name="gso",
    summary="Google Scanned Objects in look-alike families, rendered along PIN walks (the default set's scans "
            "from all 400 of a prepared folder; docs/synthetic.md)",
    licence=GSO_LICENCE, variants=("default",), make=_make, src=SRC_REQUIRED, prepare_inputs=("CHECKOUT",),
    make_source=prepare_gso))
