"""A tls:// scheduler address reaches Dask as given, and Dask's own TLS settings are what secure it."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("distributed")
import distributed  # noqa: E402

from pin_match.cli import main  # noqa: E402
from pin_match.scoring.cluster import DistributedError, connect  # noqa: E402

ADDRESS = "tls://node01.example.org:8786"


@pytest.fixture
def client_calls(monkeypatch) -> list[dict]:
    """Replace ``distributed.Client`` by one that records its arguments and finds no scheduler."""
    calls: list[dict] = []

    def recording_client(*args, **kwargs):
        calls.append(dict(args=args, **kwargs))
        raise OSError("connection refused")

    monkeypatch.setattr(distributed, "Client", recording_client)
    return calls


def test_a_tls_address_is_passed_to_the_client_unchanged(client_calls):
    with pytest.raises(DistributedError, match=f"cannot reach the Dask scheduler '{ADDRESS}' within 3 s"):
        connect(ADDRESS, timeout=3)
    # no security= of ours: the Client builds its Security from Dask's config, where the TLS settings live
    assert client_calls == [dict(args=(), address=ADDRESS, timeout=3)]


def test_the_command_line_passes_a_tls_address_unchanged(client_calls, tmp_path, capsys):
    assert main(["score", str(tmp_path), "--matcher", "sift", "--scheduler", ADDRESS, "--scheduler-timeout", "3",
                 "--out", str(tmp_path / "scores")]) == 2
    assert [call["address"] for call in client_calls] == [ADDRESS]
    assert f"pin-match score: error: cannot reach the Dask scheduler '{ADDRESS}'" in capsys.readouterr().err


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_tls_with_no_client_certificate_is_a_clear_error():
    address = f"tls://127.0.0.1:{_free_port()}"
    expected = f"Dask refuses to connect to '{address}': TLS expects .*section Security"
    with pytest.raises(DistributedError, match=expected):
        connect(address, timeout=2)


def _connect_in_child(address: str, settings: dict[str, str]) -> str:
    """connect(address)'s error in a child process with these environment variables (this one's Dask config stays)."""
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, **settings, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    script = ("import sys\nfrom pin_match.scoring.cluster import DistributedError, connect\n"
              "try:\n    connect(sys.argv[1], timeout=2)\nexcept DistributedError as exc:\n    print(exc)\n")
    run = subprocess.run([sys.executable, "-c", script, address], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return run.stdout.strip()


def test_the_client_reads_its_certificates_from_the_variables_the_docs_name(tmp_path):
    missing = tmp_path / "no-such-dir"
    settings = {"DASK_DISTRIBUTED__COMM__TLS__CA_FILE": str(missing / "ca.pem"),
                "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": str(missing / "client.pem"),
                "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": str(missing / "client.key")}
    # it tried to load the configured files, where without them Dask finds no certificate at all (test above)
    assert "No such file or directory" in _connect_in_child(f"tls://127.0.0.1:{_free_port()}", settings)


def test_required_encryption_refuses_a_plain_tcp_scheduler():
    address = f"tcp://127.0.0.1:{_free_port()}"
    assert _connect_in_child(address, {"DASK_DISTRIBUTED__COMM__REQUIRE_ENCRYPTION": "True"}).startswith(
        f"Dask refuses to connect to '{address}': encryption required by Dask configuration")
