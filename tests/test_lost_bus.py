"""Issue 16.4: a lost bus connection is a fault like any other.

python-can raises what the socket raises when a socketcand server dies (BrokenPipeError,
ConnectionResetError, OSError) from ``send`` and ``recv``. The run must try the Halt, record
the fault, end with exit 3 and leave a finished report.json and junit.xml. The fast tests
break the bus in process; the slow one kills a real ``seqrun sim serve`` mid-move.
"""

from __future__ import annotations

import itertools
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

import pytest

from projecttree import ROOT
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.service.connection import Connection
from seqrun.errors import BusError
from seqrun.results import EXIT_FAULT
from seqrun.powercube.client import PowerCubeClient
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.sim.bus import SimBus
from wrapbus import WrapBus
from zerostate import ZERO_CONFIRMED, serve_arm

_channels = itertools.count()
#: Frames sent before the connection breaks: inside the first move of opsafe.yaml.
BREAK_AFTER = 1500


def breaking_bus(clock, where: str, exc: BaseException) -> WrapBus:
    inner = SimBus(channel=f"test-lost-{next(_channels)}", clock=clock)
    state = {"broken": False}

    def check(*_):
        if bus.sends >= BREAK_AFTER:
            state["broken"] = True
            raise exc

    bus = WrapBus(inner, **{f"before_{where}": check})
    bus.flags = state
    return bus


@pytest.mark.parametrize("where, exc", [
    ("send", BrokenPipeError(32, "Broken pipe")),
    ("recv", ConnectionResetError(104, "Connection reset by peer")),
    ("recv", OSError("socket closed")),
])
def test_a_bus_that_breaks_mid_move_is_a_fault_with_exit_3_and_finished_logs(
        tmp_path, where, exc):
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    arm = load_arm(loaded.arm_path)
    clock = VirtualClock()
    bus = breaking_bus(clock, where, exc)
    connection = Connection(bus, clock, True, "simulator whose connection breaks")
    events: list[dict] = []
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               confirm=lambda prompt: True, listeners=[events.append],
                               html_report=False)
    finally:
        bus.inner.shutdown()
    assert bus.flags["broken"]
    result = outcome.result
    assert result.exit_code == EXIT_FAULT and result.status == "failed"
    fault = result.fault
    assert fault["cause"] == "bus_error"
    assert type(exc).__name__ in fault["message"]
    # The Halt was tried. A dead send path cannot send it; a dead receive path cannot
    # confirm it: either way the operator is told the Halt is not known to have worked.
    assert fault["halt_confirmed"] is False
    if where == "send":
        assert fault["halt_sent"] is False
        assert "Halt could NOT be sent" in result.message
        assert any(e["type"] == "halt_failed" for e in events)
    else:
        assert fault["halt_sent"] is True
        assert "Halt sent but NOT confirmed" in result.message
        assert any(e["type"] == "halt_unconfirmed" for e in events)
    report = RunFolder(tmp_path / "run").report()
    assert report["status"] == "failed" and report["exit_code"] == 3
    assert report["fault"]["cause"] == "bus_error"
    suite = ET.parse(tmp_path / "run" / "junit.xml").getroot()
    assert suite.find("testsuite").get("failures") == "1"


def test_the_client_turns_any_bus_exception_into_a_bus_error():
    clock = VirtualClock()
    inner = SimBus(channel=f"test-lost-{next(_channels)}", clock=clock)

    def broken(*_):
        raise BrokenPipeError(32, "Broken pipe")

    client = PowerCubeClient(WrapBus(inner, before_send=broken), clock)
    with pytest.raises(BusError, match="BrokenPipeError"):
        client.read_arm([1])
    client = PowerCubeClient(WrapBus(inner, before_recv=broken), clock)
    with pytest.raises(BusError, match="receiving from the bus failed: BrokenPipeError"):
        client.read_arm([1])
    inner.shutdown()


@pytest.mark.slow
def test_a_killed_socketcand_server_mid_move_ends_the_run_with_exit_3(tmp_path):
    server, port, env = serve_arm(tmp_path, cwd=ROOT, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True)
    try:
        folder = tmp_path / "run"
        runner = subprocess.Popen(
            [sys.executable, "-m", "seqrun", "run", "sequences/opsafe.yaml", "-i", "socketcand",
             "--bus-kwargs", f"port={port}", "--yes", *ZERO_CONFIRMED, "--plain",
             "--log-dir", str(folder)],
            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        # Kill the server once the first move is under way.
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if RunFolder(folder).events("move_planned", live=True):
                break
            time.sleep(0.05)
        time.sleep(1.0)
        server.send_signal(signal.SIGKILL)
        out, err = runner.communicate(timeout=60)
    finally:
        server.kill()
        server.wait()
    assert runner.returncode == 3, out + err
    assert "Traceback" not in out + err
    assert "FAILED (exit 3)" in out
    report = RunFolder(folder).report()
    assert report["status"] == "failed" and report["exit_code"] == 3
    assert report["fault"]["cause"] in ("bus_error", "no_acknowledge")
    assert report["fault"]["halt_confirmed"] is False
    junit = (folder / "junit.xml").read_text()
    assert junit.rstrip().endswith("</testsuites>")
