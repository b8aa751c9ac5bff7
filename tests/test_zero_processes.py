"""The zero reference end to end with real processes: a shutdown at Totem on one simulated
arm, then a start-up of an arm powered on at Totem, then a wrong record stopped by the
confirm. The arm is `seqrun sim serve` over socketcand, which seqrun treats as real
hardware (record and confirmation needed). One physical arm powered on again and again is
one serial base (``--serial-base``): the record belongs to it."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from projecttree import ROOT
from runfolder import RunFolder

pytestmark = pytest.mark.slow


def environment(state: Path) -> dict:
    env = dict(os.environ, PYTHONUNBUFFERED="1", SEQRUN_STATE_DIR=str(state))
    for key in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        env.pop(key, None)
    return env


class Server:
    def __init__(self, env: dict, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "seqrun", "sim", "serve", "--port",
                                      "0", *args], env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True)
        line = self.proc.stdout.readline()
        match = re.search(r"powered on at (\w+)\) on socketcand 127\.0\.0\.1:(\d+)", line)
        assert match, line + self.proc.stdout.read()
        self.pose, self.port = match.group(1), int(match.group(2))

    def __enter__(self) -> "Server":
        return self

    def __exit__(self, *exc) -> None:
        self.proc.terminate()
        self.proc.wait(20)
        self.proc.stdout.close()


def seqrun(env: dict, *args, stdin: str = "", timeout: float = 120):
    return subprocess.run([sys.executable, "-m", "seqrun", *map(str, args)], env=env,
                          input=stdin, capture_output=True, text=True, timeout=timeout,
                          cwd=ROOT)


def flat(text: str) -> str:
    """The output with the terminal's line wrapping undone."""
    return " ".join(text.split())


def run_on(server: Server, env: dict, sequence: str, folder: Path, *extra: str, stdin=""):
    return seqrun(env, "run", ROOT / "sequences" / sequence, "-i", "socketcand",
                  "--bus-kwargs", f"port={server.port}", "--plain", "--log-dir", folder,
                  *extra, stdin=stdin)


#: The serial numbers of the one arm of this test (module M: SERIAL_BASE + M).
SERIAL_BASE = 7_310_000


def record(server: Server, env: dict, pose: str) -> None:
    done = seqrun(env, "zero", "set", pose, "--yes", "-i", "socketcand", "--bus-kwargs",
                  f"port={server.port}")
    assert done.returncode == 0, done.stdout + done.stderr


def stage(env: dict, server_args: tuple, sequence: str, folder: Path, *extra: str,
          stdin: str = "", attempts: int = 3, before=None):
    """Run ``sequence`` on a freshly powered-on simulated arm. A run that a loaded test
    machine makes miss the 50 ms answer timeout (exit 3, "no acknowledge") is tried again
    on a fresh arm, as test_signals does; any other outcome is returned as it is."""
    for attempt in range(1, attempts + 1):
        with Server(env, "--serial-base", str(SERIAL_BASE), *server_args) as server:
            if before is not None:
                before(server)
            result = run_on(server, env, sequence, folder / f"attempt{attempt}", *extra,
                            stdin=stdin)
        if not (result.returncode == 3 and "no acknowledge" in result.stdout):
            return result
    return result


def test_shutdown_at_totem_then_start_up_then_a_wrong_record(tmp_path):
    env = environment(tmp_path / "state")
    # 1. An arm powered on at Park (recorded so), shut down: it ends in Totem, recorded.
    down = stage(env, (), "shutdown.yaml", tmp_path / "down", "--yes", "--zero-confirmed",
                 "park", before=lambda server: record(server, env, "park"))
    assert down.returncode == 0, down.stdout + down.stderr
    assert "zero: Park, recorded " in flat(down.stdout)
    with Server(env, "--serial-base", str(SERIAL_BASE), "--power-on-at", "totem") as server:
        shown = seqrun(env, "zero", "show", "-i", "socketcand", "--bus-kwargs",
                       f"port={server.port}").stdout
    assert "record   Totem, recorded " in shown and "by shutdown.yaml" in shown
    # 2. Power on at Totem: the run shows the record, the operator confirms, it works.
    up = stage(env, ("--power-on-at", "totem"), "opsafe.yaml", tmp_path / "up",
               stdin="y\ny\ny\n")
    assert up.returncode == 0, up.stdout + up.stderr
    assert re.search(r"zero: Totem, recorded \S+ \S+ by shutdown\.yaml", flat(up.stdout))
    assert "Does the arm stand in Totem now" in flat(up.stdout)
    assert "PASSED" in flat(up.stdout)  # the Op-safe checkpoint, with Totem's offsets
    # 3. A wrong record (Park) for an arm powered on at Totem: the operator says no and
    #    nothing is sent; without the confirm the checks could not have seen it.
    wrong = stage(env, ("--power-on-at", "totem"), "totem.yaml", tmp_path / "wrong",
                  stdin="y\nn\n", before=lambda server: record(server, env, "park"))
    assert wrong.returncode == 130, wrong.stdout + wrong.stderr
    assert "Does the arm stand in Park now" in flat(wrong.stdout)
    assert "Not started" in flat(wrong.stdout)
    assert RunFolder(tmp_path / "wrong" / "attempt1").trace_path() is None
