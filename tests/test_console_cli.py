"""``seqrun console`` as a command: light to load, prints its URL, serves, ends on Ctrl-C."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from projecttree import ROOT

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def start_console(*options: str) -> tuple[subprocess.Popen, str, str]:
    """``seqrun console --sim --port 0 OPTIONS``: the process, what it printed up to its
    URL and its token, and the URL (without the token: see :class:`Api`)."""
    proc = subprocess.Popen([sys.executable, "-m", "seqrun", "console", "--sim", "--port", "0",
                             *options], cwd=ROOT, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    while True:
        line = proc.stdout.readline()
        if not line:
            proc.kill()
            proc.wait()
            raise AssertionError("seqrun console ended before printing its URL:\n"
                                 + "".join(lines))
        lines.append(line)
        found = re.search(r"(http://127\.0\.0\.1:\d+/)(\?token=(\S+))?", line)
        if found:
            Api.tokens[found.group(1)] = found.group(3) or ""
            return proc, "".join(lines), found.group(1)


class Api:
    """Requests to a console started by :func:`start_console`, with its token, as a client
    that took control."""

    tokens: dict[str, str] = {}

    def __init__(self, url: str) -> None:
        self.url = url
        self.headers = {"Content-Type": "application/json",
                        "Authorization": f"Bearer {self.tokens[url]}"}
        self.headers["X-Seqrun-Control"] = self.post("control/take", {"name": "tests"})["token"]

    def post(self, path: str, body: dict | None = None) -> dict:
        request = urllib.request.Request(self.url + "api/v1/" + path, method="POST",
                                         data=json.dumps(body or {}).encode(),
                                         headers=self.headers)
        with urllib.request.urlopen(request, timeout=30) as r:
            return json.load(r)


def test_console_help_imports_no_web_stack_and_no_bus():
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "seqrun", "console",
                           "--help"], cwd=ROOT, env=ENV, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    names = {line.rsplit("|", 1)[1].strip().split(".")[0]
             for line in proc.stderr.splitlines() if line.startswith("import time:")}
    assert "seqrun" in names
    assert not names & {"fastapi", "starlette", "uvicorn", "websockets", "can", "numpy"}


def test_the_listen_address_decides_the_token():
    from seqrun.console.server import is_loopback

    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.0.2.7")


@pytest.mark.slow
def test_seqrun_console_prints_its_url_serves_and_ends_on_ctrl_c(tmp_path):
    proc, printed, url = start_console("--log-dir", str(tmp_path))
    try:
        assert "SIMULATOR" in printed
        api = Api(url)
        with urllib.request.urlopen(urllib.request.Request(
                url + "api/v1/status", headers=api.headers), timeout=10) as r:
            status = json.load(r)
        assert status["simulator"] is True and len(status["joints"]) == 7
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(urllib.request.Request(
                url + "api/v1/move/joints", data=b'{"joints": {"j1": NaN}}', method="POST",
                headers=api.headers), timeout=10)
        assert refused.value.code == 422
        assert "finite" in json.load(refused.value)["error"]
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
        assert proc.returncode == 130, out  # Ctrl-C, as for every seqrun command
        assert "ended by Ctrl-C" in out and "Traceback" not in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_local_clients_need_the_printed_token_but_stop_does_not(tmp_path):
    """On 127.0.0.1 too: any local process could otherwise command the arm."""
    proc, printed, url = start_console("--log-dir", str(tmp_path))
    try:
        printed += proc.stdout.readline()  # the line after the URL
        assert f"{url}?token=" in printed and "every request but STOP needs it" in printed
        for path, method in (("api/v1/status", "GET"), ("api/v1/control/take", "POST"),
                             ("api/v1/arm-up", "POST"), ("", "GET")):
            with pytest.raises(urllib.error.HTTPError) as refused:
                urllib.request.urlopen(urllib.request.Request(url + path, method=method,
                                                              data=b"" if method == "POST"
                                                              else None), timeout=10)
            assert refused.value.code == 401, path
        stop = urllib.request.Request(url + "api/v1/halt", method="POST", data=b"")
        with urllib.request.urlopen(stop, timeout=30) as r:
            assert json.load(r)["halt_confirmed"] is True
        # the dry-run check's worker runs from the start (no process starts mid-run)
        children = [child for task in Path(f"/proc/{proc.pid}/task").iterdir()
                    for child in (task / "children").read_text().split()]
        commands = [Path(f"/proc/{child}/cmdline").read_bytes() for child in children]
        assert any(b"spawn_main" in command for command in commands), commands
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_sigterm_during_a_move_halts_the_arm(tmp_path):
    proc, _, url = start_console("--log-dir", str(tmp_path))
    try:
        api = Api(url)
        api.post("arm-up")
        api.post("home")
        assert api.post("move/joints", {"joints": {"j1": 90}})["accepted"]
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=30)
        assert proc.returncode == 130, out
        assert "ended by SIGTERM; Halt confirmed" in out, out
        assert "Traceback" not in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_rt_priority_puts_only_the_loop_thread_at_sched_fifo(tmp_path):
    proc, printed, url = start_console("--rt-priority", "5", "--log-dir", str(tmp_path))
    try:
        assert ("the control loop at SCHED_FIFO priority 5, the console's other threads at "
                "SCHED_RR 1, the interpreter lock handed over within 1 ms") in printed
        api = Api(url)
        api.post("arm-up")
        api.post("home")
        assert api.post("move/joints", {"joints": {"j1": 60}})["accepted"]
        policies = {}
        for task in Path(f"/proc/{proc.pid}/task").iterdir():
            try:
                tid = int(task.name)
                policies[tid] = (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
            except ProcessLookupError:  # a thread that ended meanwhile
                pass
        # the move's thread (and any it started) at FIFO 5, every other thread at RR 1
        fifo = [tid for tid, policy in policies.items() if policy == (os.SCHED_FIFO, 5)]
        rr = [tid for tid, policy in policies.items() if policy == (os.SCHED_RR, 1)]
        assert fifo and len(rr) > 2 and len(fifo) + len(rr) == len(policies), policies
        api.post("halt")
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
