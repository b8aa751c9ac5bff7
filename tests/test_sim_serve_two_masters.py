"""A run through `seqrun sim serve` with `seqrun status --watch --json` beside it: the run
passes, the watch keeps going (one JSON object per refresh) and python-can's socketcand
client never warns about half elements. One controller per bus: while the run holds the
bus the watch asks the run (its readings say so), never the modules, and neither process
sees a frame of another master."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys

import pytest
from projecttree import ROOT
from zerostate import ZERO_CONFIRMED, with_park_recorded

ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


@pytest.mark.slow
def test_run_with_a_watcher_beside_it(tmp_path):
    server = subprocess.Popen([sys.executable, "-m", "seqrun", "sim", "serve", "--port", "0"],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              env=ENV)
    watcher = None
    try:
        port = int(re.search(r"127\.0\.0\.1:(\d+)", server.stdout.readline()).group(1))
        bus = ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={port}"]
        env = with_park_recorded(ENV, tmp_path, port)  # the served arm powers on at Park
        watcher = subprocess.Popen(
            [sys.executable, "-m", "seqrun", "status", "--watch", "--json", *bus],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
        # (200 ms per answer, as the README advises for a shared simulator on a loaded
        # machine: this test is about the server and the watcher, not host stalls)
        run = subprocess.run(
            [sys.executable, "-m", "seqrun", "run", "sequences/opsafe.yaml", "--yes",
             *ZERO_CONFIRMED, "--plain", "--log-dir", str(tmp_path / "run"), *bus],
            capture_output=True, text=True, env={**env, "SEQRUN_RESPONSE_TIMEOUT_MS": "200"},
            cwd=ROOT, timeout=180)
        assert watcher.poll() is None, "the watch ended during the run"
        watcher.send_signal(signal.SIGINT)
        out, err = watcher.communicate(timeout=10)
        assert run.returncode == 0, run.stdout + run.stderr
        refreshes = [json.loads(line) for line in out.splitlines()]
        assert len(refreshes) > 20
        assert all(len(r["joints"]) == 7 for r in refreshes)
        from_run = [r for r in refreshes if "from" in r]
        assert len(from_run) > 10
        assert {r["from"]["command"].split()[1] for r in from_run} == {"run"}
        for text in (run.stdout, run.stderr, err):
            assert "incomplete message" not in text
            assert "Traceback" not in text
            assert "another controller" not in text and "from another process" not in text
    finally:
        for process in (watcher, server):
            if process is not None and process.poll() is None:
                process.terminate()
                process.wait(timeout=10)
