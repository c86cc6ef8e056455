"""One JSON reader (``atomic.read_json``): every JSON file pin_match reads fails in one line, as its reader's error."""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import pytest

from pin_match import atomic
from pin_match.contract import WeightsError
from pin_match.data.frameset import FrameSetError
from pin_match.data.importer import import_recording
from pin_match.errors import PinMatchError
from pin_match.evaluation.core.analysis import AnalysisError, load_bench
from pin_match.evaluation.core.layout import BenchLayout
from pin_match.evaluation.core.sigma import SigmaError, load_threshold
from pin_match.matchers.common.fitted import read_fitted_file
from pin_match.nn.head import CONFIG_FILE, HeadError, read_head_config
from pin_match.pin_agent.recorder import INDEX, FrameRecorder, RecordingError

DAMAGED = b'{"matcher": "sift", "sig'  # a write cut short


class ToyError(PinMatchError):
    pass


def test_the_reader_names_what_and_where_as_the_callers_error(tmp_path):
    good = tmp_path / "good.json.gz"
    good.write_bytes(gzip.compress(b'{"a": [1, 2]}'))
    assert atomic.read_json(good, ToyError) == {"a": [1, 2]}
    cases = {
        "cut.json": (DAMAGED, "Unterminated string"),
        "latin.json": ('{"name": "caf\u00e9"}'.encode("latin-1"), "codec can't decode"),
        "cut.json.gz": (gzip.compress(b'{"a": 1}')[:-6], "end-of-stream|Compressed file ended"),
        "plain.json.gz": (b'{"a": 1}', "Not a gzipped file"),
    }
    for name, (data, why) in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ToyError, match=rf"^cannot read toy file {re.escape(str(tmp_path / name))} as JSON: "
                                           rf".*({why})") as err:
            atomic.read_json(tmp_path / name, ToyError, "toy file")
        assert "\n" not in str(err.value)
    with pytest.raises(ToyError, match=rf"^missing toy file {re.escape(str(tmp_path / 'none.json'))}$"):
        atomic.read_json(tmp_path / "none.json", ToyError, "toy file")
    with pytest.raises(ToyError, match=r"^cannot read file .* as JSON: \[Errno 21\]"):
        atomic.read_json(tmp_path, ToyError)  # a folder


def _damaged(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(DAMAGED)
    return path


def _recording(root: Path) -> None:
    _damaged(root / "recording" / "episodes.json")


def _descriptions(root: Path) -> None:
    (root / "recording").mkdir()
    (root / "recording" / "episodes.json").write_text('{"episodes": []}')
    _damaged(root / "objects" / "objects_descriptions.json")


def _import(root: Path) -> None:
    import_recording(root / "recording", root / "objects", root / "out")


def _gz_recording(root: Path) -> None:
    (root / "recording").mkdir()
    (root / "recording" / "episodes.json.gz").write_bytes(gzip.compress(b'{"episodes": [')[:-4])


def _recorder(root: Path) -> None:
    FrameRecorder(root).finished_episodes()


# (what to damage, how to read it, the reader's error, what the message calls the file)
READERS = {
    "thresholds": (lambda root: _damaged(root / "sift.json"), lambda root: load_threshold(root / "sift.json", "sift"),
                   SigmaError, "thresholds file", "sift.json"),
    "fitted file": (lambda root: _damaged(root / "v.json"),
                    lambda root: read_fitted_file(root / "v.json", "verifier", "pin-match-verifier", 2),
                    WeightsError, "verifier file", "v.json"),
    "recording episodes": (_recording, _import, FrameSetError, "PInNED episodes file", "recording/episodes.json"),
    "recording episodes, gzip": (_gz_recording, _import, FrameSetError, "PInNED episodes file",
                                 "recording/episodes.json.gz"),
    "object descriptions": (_descriptions, _import, FrameSetError, "file", "objects/objects_descriptions.json"),
    "recorder's episode list": (lambda root: _damaged(root / INDEX), _recorder, RecordingError,
                                "the recording's episode list", INDEX),
    "head config": (lambda root: _damaged(root / CONFIG_FILE), read_head_config, HeadError, "file", CONFIG_FILE),
    "bench thresholds": (lambda root: _damaged(BenchLayout(root).thresholds("sift")),
                         lambda root: load_threshold(BenchLayout(root).thresholds("sift"), "sift"),
                         SigmaError, "thresholds file", "thresholds/sift.json"),
}


@pytest.mark.parametrize("reader", sorted(READERS))
def test_a_damaged_json_file_is_named_in_its_readers_error(tmp_path, reader):
    damage, read, error, what, name = READERS[reader]
    damage(tmp_path)
    with pytest.raises(error, match=rf"^cannot read {re.escape(what)} {re.escape(str(tmp_path / name))} as JSON: "):
        read(tmp_path)


def test_a_damaged_report_of_a_bench_folder_is_named(tmp_path, tiny_frameset):
    layout = BenchLayout(tmp_path)
    path = _damaged(layout.report("sift") / "metrics.json")
    with pytest.raises(AnalysisError, match=rf"^cannot read report {re.escape(str(path))} as JSON: "):
        load_bench(layout, tiny_frameset)
