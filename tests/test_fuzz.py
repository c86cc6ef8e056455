"""Property-based fuzzing of frame-sets and recordings (issue 14.12): damage in, one named error out.

Hypothesis draws a sequence of damages (delete a file, truncate it, overwrite it with other
bytes, replace a JSON value by one of the wrong type, drop or blank a table row, write a
wrong-typed cell) on a copy of a valid frame-set or PIN recording, then runs the CLI on it.
Every case must end in exit code 0 (the damage did not matter) or 2 with one line naming
the problem, never a traceback; and nothing may be half-written: a failed import leaves
no frame-set and no staging folder, a failed score leaves no table and no temporary file.
The numbers of cases are in docs/reliability.md.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from toys import write_recording

from pin_match.cli import main

FRAMESET_CASES = 40
RECORDING_CASES = 60
WRONG_VALUES = st.sampled_from([None, "", "x", -1, 0, 3.5, 10**12, [], {}, ["a"], {"a": 1}, True, "../../etc"])


# ------------------------------------------------------------------ damages
STRUCTURE = (".json", ".csv", ".parquet", ".gz", ".npy")


@st.composite
def damages(draw, files: list[Path]) -> list[tuple]:
    """A list of (kind, file, argument) to apply in order; half of them hit the tables, JSON and arrays."""
    kinds = st.sampled_from(["delete", "truncate", "garbage", "json", "drop_row", "cell", "column"])
    structure = [f for f in files if f.suffix in STRUCTURE]
    out = []
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(kinds)
        pool = structure if structure and draw(st.integers(0, 2)) else files
        index = pool[draw(st.integers(0, len(pool) - 1))]
        if kind == "truncate":
            arg = draw(st.floats(0.0, 0.95))
        elif kind == "garbage":
            arg = draw(st.binary(min_size=0, max_size=64))
        elif kind in ("json", "cell", "column"):
            arg = (draw(st.integers(0, 10**6)), draw(WRONG_VALUES))
        else:
            arg = draw(st.integers(0, 10**6))
        out.append((kind, index, arg))
    return out


def _json_paths(data, prefix=()) -> list[tuple]:
    """Every (path) into nested dicts / lists, the root excluded."""
    out = []
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, list) else []
    for key, value in items:
        out.append((*prefix, key))
        out.extend(_json_paths(value, (*prefix, key)))
    return out


def _damage(path: Path, kind: str, arg) -> None:
    if not path.exists():
        return
    if kind == "delete":
        path.unlink()
    elif kind == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[:int(len(data) * arg)])
    elif kind == "garbage":
        path.write_bytes(arg)
    elif kind == "json" and path.suffix == ".json" and _readable(path):
        data = json.loads(path.read_text())
        paths = [(), *_json_paths(data)]  # () replaces the whole document
        where = paths[arg[0] % len(paths)]
        if not where:
            data = arg[1]
        else:
            node = data
            for key in where[:-1]:
                node = node[key]
            node[where[-1]] = arg[1]
        path.write_text(json.dumps(data))
    elif kind in ("drop_row", "cell", "column") and path.suffix in (".parquet", ".csv") and _readable(path):
        df = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path, dtype=str)
        if df.empty:
            return
        seed = arg if kind == "drop_row" else arg[0]
        row = seed % len(df)
        if kind == "drop_row":
            df = df.drop(index=df.index[row])
        elif kind == "column":  # a whole column of the wrong type
            df[df.columns[seed % len(df.columns)]] = [arg[1]] * len(df)
        else:
            col = df.columns[(seed // len(df)) % len(df.columns)]
            df[col] = df[col].astype(object)
            df.at[df.index[row], col] = arg[1]
        try:
            df.to_parquet(path) if path.suffix == ".parquet" else df.to_csv(path, index=False)
        except Exception:  # pyarrow cannot store this mix of types: store the column as text instead
            df = df.astype(str)
            df.to_parquet(path) if path.suffix == ".parquet" else df.to_csv(path, index=False)
    elif kind in ("json", "drop_row", "cell", "column"):  # not a table or JSON: flip a byte instead
        data = bytearray(path.read_bytes())
        if data:
            data[arg[0] % len(data) if isinstance(arg, tuple) else arg % len(data)] ^= 0xFF
            path.write_bytes(bytes(data))


def _readable(path: Path) -> bool:
    """Whether an earlier damage of the same plan (a truncation, garbage) left the JSON or table readable to edit."""
    try:
        if path.suffix == ".json":
            json.loads(path.read_text())
        else:
            pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path, dtype=str)
    except Exception:  # json, pyarrow and pandas raise many kinds on a damaged file
        return False
    return True


def _files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.is_file())


@contextlib.contextmanager
def _damaged_copy(source: Path, plan: list[tuple], name: str) -> Iterator[tuple[Path, Path]]:
    """(a temporary folder, the copy of ``source`` in it named ``name`` with ``plan``'s damages done)."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / name
        shutil.copytree(source, root)
        for kind, file, arg in plan:
            _damage(root / file, kind, arg)
        yield Path(tmp), root


def _fuzz(cases: int):
    """Hypothesis settings of a damage test: ``cases`` drawn plans, the same ones every run, no time limit."""
    return settings(max_examples=cases, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _check_outcome(capsys, rc: int, command: str) -> str:
    err = capsys.readouterr().err
    assert rc in (0, 2), f"exit code {rc}: {err}"
    if rc == 2:
        lines = [line for line in err.splitlines() if line.startswith(f"pin-match {command}: error:")]
        assert len(lines) == 1 and "Traceback" not in err, err
    return err


# ------------------------------------------------------------------ frame-sets
@pytest.fixture(scope="module")
def frameset_files(tiny_frameset):
    return tiny_frameset.root, [p.relative_to(tiny_frameset.root) for p in _files(tiny_frameset.root)]


@_fuzz(FRAMESET_CASES)
@given(data=st.data())
def test_damaged_frameset_ends_in_a_named_error(frameset_files, capsys, data):
    source, files = frameset_files
    with _damaged_copy(source, data.draw(damages(files)), "fs") as (tmp, root):
        out = tmp / "scores"
        rc = main(["score", str(root), "--matcher", "test-slow", "--cfg", "delay=0", "--out", str(out), "--quiet",
                   "--workers", "1"])
        _check_outcome(capsys, rc, "score")
        tables = list(out.rglob("scores_all.parquet")) if out.exists() else []
        assert not [p for p in out.rglob("*.tmp")] if out.exists() else True
        if rc != 0:
            assert not tables  # no table of a failed run
            return
        rc = main(["report", str(tables[0]), "--frameset", str(root), "--threshold", "100", "--bootstrap", "5",
                   "--out", str(tmp / "report")])
        _check_outcome(capsys, rc, "report")
        if rc != 0:
            assert not (tmp / "report" / "metrics.json").exists() or rc == 0


# ------------------------------------------------------------------ recordings
@pytest.fixture(scope="module")
def recording_files(tmp_path_factory):
    root = tmp_path_factory.mktemp("recording")
    write_recording(root, steps=2, shape=(24, 16), view_size=32)
    return root, [p.relative_to(root) for p in _files(root)]


@_fuzz(RECORDING_CASES)
@given(data=st.data())
def test_damaged_recording_ends_in_a_named_error(recording_files, capsys, data):
    source, files = recording_files
    with _damaged_copy(source, data.draw(damages(files)), "in") as (tmp, root):
        out = tmp / "out" / "fs"
        rc = main(["import", str(root / "rec"), "--objects", str(root / "objects"), "--out", str(out)])
        _check_outcome(capsys, rc, "import")
        leftovers = [p.name for p in (tmp / "out").iterdir()] if (tmp / "out").exists() else []
        if rc == 0:
            assert leftovers == ["fs"]
        else:
            assert leftovers == []  # no frame-set, no staging folder

