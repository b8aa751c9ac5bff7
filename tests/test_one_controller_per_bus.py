"""One controller per bus, with real processes on `seqrun sim serve` (served as a real arm):
a second controller is refused naming the holder; `seqrun status` and `seqrun halt` in
another terminal talk to the run; another master's frame halts the run; a killed holder
leaves no claim behind."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import can
import pytest
from runfolder import RunFolder
from zerostate import ZERO_CONFIRMED, serve_arm

from seqrun.service.bus_claim import read_holder
from seqrun.service.control_socket import ask_owner

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow


class Bus:
    """A served arm, its bus options, and an environment with its own runtime directory."""

    def __init__(self, tmp_path: Path) -> None:
        self.runtime = Path(tempfile.mkdtemp(prefix="sq", dir="/tmp"))  # short socket paths
        self.server, self.port, env = serve_arm(tmp_path, cwd=ROOT)
        # (200 ms per answer: a shared simulator on a loaded machine; see the README)
        self.env = {**env, "SEQRUN_RUNTIME_DIR": str(self.runtime),
                    "SEQRUN_RESPONSE_TIMEOUT_MS": "200", "PYTHONUNBUFFERED": "1"}
        self.args = ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={self.port}"]
        self.key = ("socketcand", f"127.0.0.1:{self.port}/can0")
        self.name = f"socketcand:127.0.0.1:{self.port}/can0"

    def seqrun(self, *args: str, timeout: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "seqrun", *args, *self.args], cwd=ROOT,
                              env=self.env, capture_output=True, text=True, timeout=timeout)

    def start_run(self, folder: Path) -> subprocess.Popen:
        return subprocess.Popen(
            # (a quarter of the speed: the run lasts about a minute, long enough for the
            # other terminal's commands on a loaded machine)
            [sys.executable, "-m", "seqrun", "run", "sequences/opsafe.yaml", "--yes",
             "--plain", "--speed", "0.25", "--no-report", "--log-dir", str(folder), *self.args,
             *ZERO_CONFIRMED],
            cwd=ROOT, env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    def wait_until_moving(self, run: subprocess.Popen, timeout: float = 60) -> dict:
        """The run's own status once it streams a move (asked over its socket)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            assert run.poll() is None, run.stdout.read()
            reply = ask_owner(*self.key, "status", directory=self.runtime)
            if reply and reply.get("ok"):
                status = reply["status"]
                if (status["step"] or {}).get("step", 0) >= 5 and any(
                        abs(j["velocity_deg_s"] or 0) > 0.5 for j in status["joints"]):
                    return reply
            time.sleep(0.1)
        raise AssertionError("the run did not start moving")

    def close(self) -> None:
        import shutil

        self.server.kill()
        self.server.wait(timeout=10)
        shutil.rmtree(self.runtime, ignore_errors=True)


@pytest.fixture
def bus(tmp_path):
    served = Bus(tmp_path)
    yield served
    served.close()


def _finish(run: subprocess.Popen, timeout: float = 120) -> str:
    try:
        out, _ = run.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        run.kill()
        raise
    return out


def test_second_controller_refused_status_and_halt_through_the_run(bus, tmp_path):
    run = bus.start_run(tmp_path / "run")
    try:
        bus.wait_until_moving(run)
        holder = read_holder(*bus.key, directory=bus.runtime)
        assert holder.pid == run.pid and holder.command.startswith(
            "seqrun run sequences/opsafe.yaml --yes --plain --speed 0.25")
        # A second run and a Reset are refused: one line naming the holder, exit 2.
        for args in (("run", "sequences/opsafe.yaml", "--yes", "--plain",
                      "--log-dir", str(tmp_path / "second")), ("reset",)):
            refused = bus.seqrun(*args)
            assert refused.returncode == 2, refused.stdout + refused.stderr
            lines = refused.stderr.strip().splitlines()
            assert len(lines) == 1 and re.fullmatch(
                rf"error: {re.escape(bus.name)} is held by pid {run.pid} "
                rf"\(seqrun run sequences/opsafe\.yaml .*\) since \d\d:\d\d:\d\d: one "
                r"controller per bus; 'seqrun status' and 'seqrun halt' talk to it",
                lines[0]), lines
            assert "Traceback" not in refused.stdout + refused.stderr
        assert RunFolder(tmp_path / "second").trace_path() is None
        # status: the run answers (the same shape as a reading of the bus), as JSON and
        # as the table.
        status = bus.seqrun("status", "--json")
        assert status.returncode == 0, status.stderr
        reading = json.loads(status.stdout)
        assert reading["from"]["pid"] == run.pid
        assert [j["joint"] for j in reading["joints"]] == [f"j{k}" for k in range(1, 8)]
        assert {"position_deg", "velocity_deg_s", "state", "fault", "stale"} <= \
            set(reading["joints"][0])
        assert len(reading["end_effector"]["position_mm"]) == 3
        table = bus.seqrun("status")
        assert table.returncode == 0 and f"via the running seqrun (pid {run.pid}" in \
            table.stdout.splitlines()[0]
        # halt: broadcast straight to the bus, confirmed by the run; the run ends halted.
        halt = bus.seqrun("halt")
        t0 = time.monotonic()
        assert halt.returncode == 0, halt.stdout + halt.stderr
        assert re.match(rf"Halt confirmed by modules 1, 2, 3, 4, 5, 6, 7, read back by the "
                        rf"running seqrun \(pid {run.pid}", halt.stdout.splitlines()[-1]), \
            halt.stdout
        out = _finish(run, timeout=60)
        took = time.monotonic() - t0
        assert run.returncode == 3, out
        assert took < 10, took   # the run had halted already: it only reports and exits
        # Named by whichever reached the run first: the broadcast it read on the bus, or
        # the request on its socket.
        assert re.search(r"FAILED \(exit 3\): (Halt broadcast from another process \(frame "
                         r"0x100 \[02 00\]\)|seqrun halt from another process \(pid \d+\))",
                         out), out
        report = json.loads((tmp_path / "run" / "report.json").read_text())
        assert report["fault"]["cause"] == "remote_halt"
        assert report["fault"]["halt_confirmed"] is True
    finally:
        if run.poll() is None:
            run.kill()
    # The run is over: its claim went with it, status reads the bus itself.
    assert read_holder(*bus.key, directory=bus.runtime) is None
    after = bus.seqrun("status", "--json")
    assert after.returncode == 0 and "from" not in json.loads(after.stdout)
    assert all("HALTED" in j["state"] for j in json.loads(after.stdout)["joints"])


def test_a_foreign_request_frame_during_a_run_halts_it(bus, tmp_path):
    run = bus.start_run(tmp_path / "run")
    try:
        bus.wait_until_moving(run)
        # This test process is a second master that knows nothing of claims.
        with can.Bus(interface="socketcand", host="127.0.0.1", port=bus.port, channel="can0",
                     ignore_config=True) as other:
            other.send(can.Message(arbitration_id=0x0C3, data=b"\x0a\x62",
                                   is_extended_id=False))
            t0 = time.monotonic()
            out = _finish(run, timeout=30)
        assert run.returncode == 3, out
        assert time.monotonic() - t0 < 10
        assert ("another controller is on the bus (frame 0x0C3 [0A 62]: GetExtended "
                "FPOS_STATE_DIO to module 3)") in out
        report = json.loads((tmp_path / "run" / "report.json").read_text())
        assert report["fault"]["cause"] == "foreign_master"
        assert report["fault"]["halt_sent"] is True
    finally:
        if run.poll() is None:
            run.kill()


def test_a_killed_holder_leaves_the_bus_free(bus, tmp_path):
    run = bus.start_run(tmp_path / "run")
    try:
        bus.wait_until_moving(run)
        run.send_signal(signal.SIGKILL)
        run.wait(timeout=10)
    finally:
        if run.poll() is None:
            run.kill()
    # Its record is left on disk; the kernel dropped the lock with the process.
    assert read_holder(*bus.key, directory=bus.runtime).pid == run.pid
    status = bus.seqrun("status", "--json")
    assert status.returncode == 0, status.stderr
    assert "from" not in json.loads(status.stdout)
    halt = bus.seqrun("halt")
    assert halt.returncode == 0, halt.stdout + halt.stderr
    headline, confirmed = halt.stdout.splitlines()
    assert headline.startswith("arm ") and "socketcand" in headline   # which arm and bus
    assert confirmed.startswith("Halt confirmed by modules 1, 2, 3, 4, 5, 6, 7 (")
