"""``--foxglove=PORT`` right after a Foxglove client left (issue 43, item 5): the port is
in TIME_WAIT, which the server's own bind accepts (SO_REUSEADDR); the check made before
anything opens must accept it too, and still refuse a port somebody listens on."""

from __future__ import annotations

import socket

from typer.testing import CliRunner

from projecttree import ROOT
from seqrun.cli import app


def port_in_time_wait() -> int:
    """A loopback port whose server closed a connection first, as the Foxglove server does
    when its client goes: the port stays in TIME_WAIT for a minute."""
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    client = socket.create_connection(("127.0.0.1", port))
    accepted, _ = server.accept()
    accepted.close()
    client.close()
    server.close()
    with socket.socket() as plain:   # (without SO_REUSEADDR the port is refused)
        try:
            plain.bind(("127.0.0.1", port))
        except OSError:
            return port
    raise AssertionError(f"port {port} is not in TIME_WAIT")


def run_with_foxglove(port: int, tmp_path):
    return CliRunner().invoke(app, [
        "run", str(ROOT / "sequences" / "opsafe.yaml"), "--yes", "--virtual-time", "--plain",
        "--no-report", f"--foxglove={port}", "--log-dir", str(tmp_path / "runs")])


def test_foxglove_port_just_left_by_a_client_is_served(tmp_path):
    result = run_with_foxglove(port_in_time_wait(), tmp_path)
    assert result.exit_code == 0, result.output
    assert "Foxglove live on ws://127.0.0.1:" in result.output


def test_foxglove_port_with_a_listener_is_refused_in_one_line(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        result = run_with_foxglove(port, tmp_path)
    assert result.exit_code == 2, result.output
    assert result.output.strip() == (f"error: --foxglove: cannot listen on 127.0.0.1:{port}: "
                                     "Address already in use")
