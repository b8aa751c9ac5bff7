"""Questions, signals and endings (issue 23, item 5).

- SIGTERM / SIGHUP / SIGQUIT while ``seqrun run`` asks before a REAL arm or about the zero
  reference: one line, exit 130, a run folder saying nothing was sent (they killed it
  without a word and left no trace).
- Ctrl-C after a run has ended never turns its exit code into 130 nor says "nothing was
  sent" (a faulted run's exit 3 became 130).
- An empty stdin at a question is a "no", with the exit of declining (click said
  "Aborted!", exit 1, at ``seqrun zero set``).
- A run refused for schema errors ends with the "nothing was sent" line, as one refused
  by validation does.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
import seqrun.cli.run as cli_run
from projecttree import ROOT, make_project
from seqrun.cli.app import app
from seqrun.service.session import ArmSession

TOTEM = ROOT / "sequences" / "totem.yaml"


def invoke(*args, **kwargs):
    return CliRunner().invoke(app, [str(a) for a in args], **kwargs)


# ----------------------------------------------------------------------------- endings
def test_a_run_refused_for_schema_errors_ends_with_nothing_was_sent(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: B\ndescription: x\nsteps:\n  - movve: totem\n")
    result = invoke("run", bad, "--virtual-time", "--yes")
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert lines[0].startswith("error: ") and "unknown step type 'movve'" in lines[0]
    assert lines[-1].endswith("invalid (1 error); nothing was sent"), lines


@pytest.mark.parametrize("fault, code", [("4:tow_error@3", 3), (None, 0)])
def test_ctrl_c_after_the_run_ended_keeps_its_exit_code(tmp_path, monkeypatch, fault, code):
    """Ctrl-C while the verdict is printed: the run has ended, its exit code stands."""
    real_print = cli_run._print_outcome

    def print_then_ctrl_c(*args, **kwargs):
        real_print(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(cli_run, "_print_outcome", print_then_ctrl_c)
    extra = ["--sim-fault", fault] if fault else []
    result = invoke("run", TOTEM, "--virtual-time", "--yes", "--plain", "--no-report",
                    "--log-dir", tmp_path / "run", *extra)
    assert result.exit_code == code, result.output
    assert "nothing was sent" not in result.output


def test_ctrl_c_while_the_run_closes_is_still_a_request(tmp_path, monkeypatch):
    """A real SIGINT while the session closes (after the run, before the verdict): the
    run's handlers are still in place, so it cannot become a KeyboardInterrupt."""
    real_close = ArmSession.close

    def close_with_ctrl_c(self, *args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return real_close(self, *args, **kwargs)

    monkeypatch.setattr(ArmSession, "close", close_with_ctrl_c)
    result = invoke("run", TOTEM, "--virtual-time", "--yes", "--plain", "--no-report",
                    "--log-dir", tmp_path / "run", "--sim-fault", "4:tow_error@3")
    assert result.exit_code == 3, result.output
    assert "FAILED (exit 3)" in result.output and "nothing was sent" not in result.output


# ----------------------------------------------------------------------------- empty stdin
def test_an_empty_stdin_at_a_confirm_step_is_a_no_like_declining(tmp_path):
    empty = invoke("run", TOTEM, "--virtual-time", "--plain", "--no-report", "--log-dir",
                   tmp_path / "a", input="")
    declined = invoke("run", TOTEM, "--virtual-time", "--plain", "--no-report", "--log-dir",
                      tmp_path / "b", input="n\n")
    assert empty.exit_code == declined.exit_code == 130, (empty.output, declined.output)
    assert "clear for the move to Totem? [y/N] (no answer: end of input) no" in empty.output


def test_an_empty_stdin_at_zero_set_is_a_no_like_declining(tmp_path, monkeypatch):
    from seqrun.clock import RealClock
    from seqrun.sim.arm import SimArm
    from seqrun.sim.network import SimNetwork
    from seqrun.sim.socketcand import SocketcandServer

    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    monkeypatch.chdir(tmp_path)
    clock = RealClock()
    server = SocketcandServer(SimNetwork(clock, SimArm(clock), spin_window=0.0), port=0)
    server.start()
    try:
        bus = ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={server.port}"]
        empty = invoke("zero", "set", "park", *bus, input="")
        declined = invoke("zero", "set", "park", *bus, input="n\n")
    finally:
        server.shutdown()
    assert empty.exit_code == declined.exit_code == 130, (empty.output, declined.output)
    assert "Aborted" not in empty.output
    assert "(no answer: end of input) no" in empty.output
    assert "error: nothing recorded" in empty.output


# ----------------------------------------------------------------------------- signals
def _seqrun(*args, cwd: Path, stdin=subprocess.DEVNULL) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1", SEQRUN_STATE_DIR=str(cwd / "zero-state"),
               PYTHONPATH=str(ROOT))
    for key in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        env.pop(key, None)
    return subprocess.Popen([sys.executable, "-m", "seqrun", *map(str, args)], cwd=cwd,
                            env=env, stdin=stdin, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


class _Output:
    """A process's stdout, read as it comes (questions end without a newline)."""

    def __init__(self, stream) -> None:
        self.text = ""
        self._lock = threading.Lock()
        threading.Thread(target=self._pump, args=(stream,), daemon=True).start()

    def _pump(self, stream) -> None:
        while True:
            chunk = stream.read(1)
            if not chunk:
                return
            with self._lock:
                self.text += chunk

    def wait_for(self, text: str, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if text in self.text:
                    return
            time.sleep(0.05)
        pytest.fail(f"{text!r} not seen within {timeout} s: {self.text!r}")


def _end(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=10)


@pytest.mark.slow
@pytest.mark.parametrize("question", ["real", "zero"])
@pytest.mark.parametrize("name", ["SIGTERM", "SIGHUP", "SIGQUIT"])
def test_a_signal_at_a_question_before_the_run_is_one_line_and_exit_130(tmp_path, name,
                                                                        question):
    project = make_project(tmp_path / "project", sequences=("startup.yaml", "totem.yaml"))
    sequence = project / "sequences" / "totem.yaml"
    folder = tmp_path / "run"
    server = _seqrun("sim", "serve", "--port", "0", cwd=tmp_path)
    runner = None
    try:
        served = _Output(server.stdout)
        served.wait_for("socketcand 127.0.0.1:")
        time.sleep(0.2)
        port = served.text.split("socketcand 127.0.0.1:")[1].split()[0].strip(" ,;)")
        if question == "zero":  # a record: after the power-on its pose is asked about
            recorded = _seqrun("zero", "set", "park", "--yes", "--project", project,
                               "-i", "socketcand", "--bus-kwargs", f"port={int(port)}",
                               cwd=tmp_path)  # (the record belongs to the served arm)
            assert recorded.wait(60) == 0, recorded.communicate()
        runner = _seqrun("run", sequence, "-i", "socketcand", "--bus-kwargs",
                         f"port={int(port)}", "--plain", "--log-dir", folder, cwd=tmp_path,
                         stdin=subprocess.PIPE)
        out = _Output(runner.stdout)
        out.wait_for("on the REAL arm? [y/N] ")
        if question == "zero":
            runner.stdin.write("y\n")
            runner.stdin.flush()
            out.wait_for("Does the arm ")
            out.wait_for("[y/N] ")
        time.sleep(0.3)  # it waits for the answer
        runner.send_signal(getattr(signal, name))
        code = runner.wait(timeout=30)
        err = runner.stderr.read()
    finally:
        if runner is not None:
            _end(runner)
        if server.poll() is None:
            server.send_signal(signal.SIGINT)
            try:
                server.wait(timeout=10)
            except subprocess.TimeoutExpired:
                _end(server)
    assert code == 130, (code, out.text, err)
    assert err.strip().splitlines() == [
        f"seqrun run: {name} before the run started; nothing was sent"], err
    report = json.loads((folder / "report.json").read_text())
    assert report["status"] == "aborted" and report["exit_code"] == 130
    assert report["nothing_sent"] is True and "nothing was sent" in report["message"]
    assert not (folder / "trace.log").exists()
    assert (folder / "record.json").is_file()
