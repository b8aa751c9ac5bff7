"""``--bus-kwargs`` as python-can's tools take it: several KEY=VALUE after one flag; bad
values are one line and exit 2."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from projecttree import ROOT
from seqrun.cli import app
from seqrun.cli.argv import expand_bus_kwargs
from seqrun.clock import RealClock
from seqrun.sim.arm import SimArm
from seqrun.sim.network import SimNetwork
from seqrun.sim.socketcand import SocketcandServer


@pytest.fixture
def server():
    clock = RealClock()
    with SocketcandServer(SimNetwork(clock, SimArm(clock), spin_window=0.0), port=0) as srv:
        srv.start()
        yield srv


def test_expand_bus_kwargs():
    assert expand_bus_kwargs(["status", "--bus-kwargs", "host=h", "port=1", "--json"]) == [
        "status", "--bus-kwargs", "host=h", "--bus-kwargs", "port=1", "--json"]
    assert expand_bus_kwargs(["run", "--bus-kwargs=a=1", "b=2", "seq.yaml"]) == [
        "run", "--bus-kwargs=a=1", "--bus-kwargs", "b=2", "seq.yaml"]
    # a file argument, options and anything after "--" stay as they are
    assert expand_bus_kwargs(["run", "x.yaml", "--bus-kwargs", "a=1", "-i", "k=v"]) == [
        "run", "x.yaml", "--bus-kwargs", "a=1", "-i", "k=v"]
    assert expand_bus_kwargs(["--bus-kwargs", "a=1", "--", "b=2"]) == [
        "--bus-kwargs", "a=1", "--", "b=2"]


def test_several_key_values_after_one_flag(server):
    result = CliRunner().invoke(app, ["status", "--json", "-i", "socketcand", "--bus-kwargs",
                                      "host=127.0.0.1", f"port={server.port}"])
    assert result.exit_code == 0, result.output
    assert '"joints"' in result.output


@pytest.mark.parametrize(("args", "message"), [
    (["-i", "socketcand", "--bus-kwargs", "port=abc"], "Port config must be a number"),
    (["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", "port=abc"], "must be a number"),
    (["--bus-kwargs", "port=abc"], "--bus-kwargs port: the built-in simulator"),
    (["--bus-kwargs", "home_ok_at_power_on=maybe"], "expected true or false"),
])
@pytest.mark.parametrize("command", [["status"], ["halt"], ["reset"]])
def test_bad_bus_kwargs_are_one_line_exit_2(command, args, message):
    result = CliRunner().invoke(app, [*command, *args])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and result.exception is None or isinstance(
        result.exception, SystemExit)
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0]


def test_bad_bus_kwargs_in_run(tmp_path):
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"), "--yes",
                                      "--log-dir",
                                      str(tmp_path / "log"), "-i", "socketcand",
                                      "--bus-kwargs", "port=abc"])
    assert result.exit_code == 2, result.output
    assert "must be a number" in result.output and "Traceback" not in result.output
