"""``seqrun status`` / ``status --watch`` / ``halt`` beside a console that holds the bus
(issue 23, "Beside the console"): the console's session answers over the control socket in
the same shapes a run does, so status prints its table and halt says "confirmed", exit 0."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from projecttree import shipped_arm
from seqrun.cli import app
from seqrun.clock import RealClock
from seqrun.service import ArmSession
from seqrun.service.connection import open_connection
from seqrun.service.control_socket import serve_control
from seqrun.sim.arm import SimArm
from seqrun.sim.network import SimNetwork
from seqrun.sim.socketcand import SocketcandServer


@pytest.fixture
def console_session(tmp_path, monkeypatch):
    """What ``seqrun console -i socketcand`` holds: an arm session on a claimed shared bus,
    its control socket served (seqrun/cli/console.py)."""
    monkeypatch.setenv("SEQRUN_RUNTIME_DIR", str(tmp_path / "rt"))
    clock = RealClock()
    server = SocketcandServer(SimNetwork(clock, SimArm(clock), spin_window=0.0), port=0)
    server.start()
    connection = open_connection(interface="socketcand",
                                 bus_kwargs={"host": "127.0.0.1", "port": server.port})
    session = ArmSession(shipped_arm(), connection, status_hz=0, log_root=tmp_path / "runs")
    session.poll_status()
    serve_control(connection.claim, session.control_handler())
    yield server, session
    session.close()
    server.shutdown()


def _args(server) -> list[str]:
    return ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={server.port}"]


def test_status_beside_the_console_prints_its_reading(console_session):
    server, _ = console_session
    result = CliRunner().invoke(app, ["status", *_args(server)])
    assert result.exit_code == 0, result.output
    assert "via the running seqrun" in result.output
    assert "-90.000" in result.output   # j2 at Park, from the console's measurement


def test_status_watch_json_beside_the_console(console_session):
    server, _ = console_session
    result = CliRunner().invoke(app, ["status", "--watch", "--json", "--count", "2",
                                      "--period", "0", *_args(server)])
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in result.output.strip().splitlines()]
    assert len(lines) == 2
    assert lines[0]["joints"][1]["joint"] == "j2"
    assert lines[0]["joints"][1]["position_deg"] == pytest.approx(-90.0)
    assert lines[0]["joints"][1]["state"]


def test_halt_beside_the_console_is_confirmed_exit_0(console_session):
    server, session = console_session
    result = CliRunner().invoke(app, ["halt", *_args(server)])
    assert result.exit_code == 0, result.output
    assert "Halt confirmed by modules 1, 2, 3, 4, 5, 6, 7" in result.output
    assert "not confirm" not in result.output
    session.poll_status()
    assert all("HALTED" in j.flags for j in session.status().joints)
