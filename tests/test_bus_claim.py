"""One controller per bus: the claim (lock + holder record) and its refusal line."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from seqrun.errors import Refused
from seqrun.service.bus_claim import claim_bus, command_line, read_holder, runtime_dir

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def rundir(tmp_path, monkeypatch):
    folder = tmp_path / "rt"
    monkeypatch.setenv("SEQRUN_RUNTIME_DIR", str(folder))
    return folder


def test_a_second_claim_is_refused_with_one_line_naming_the_holder(rundir):
    with claim_bus("socketcan", "can0", "seqrun run totem.yaml") as first:
        with pytest.raises(Refused) as refused:
            claim_bus("socketcan", "can0", "seqrun reset")
        text = str(refused.value)
        assert "\n" not in text
        assert re.fullmatch(
            rf"socketcan:can0 is held by pid {os.getpid()} \(seqrun run totem\.yaml\) since "
            r"\d\d:\d\d:\d\d: one controller per bus; 'seqrun status' and 'seqrun halt' "
            r"talk to it", text), text
        assert first.holder().pid == os.getpid()
        # Another bus (channel, or the same channel behind another interface) is free.
        with claim_bus("socketcan", "can1", "x"), claim_bus("socketcand",
                                                              "127.0.0.1:29536/can0", "y"):
            pass
    # Released: the record is gone and the next claim succeeds.
    assert read_holder("socketcan", "can0") is None
    with claim_bus("socketcan", "can0", "seqrun reset"):
        assert read_holder("socketcan", "can0").command == "seqrun reset"


def test_the_record_names_pid_command_argv_time_and_socket(rundir):
    before = time.time()
    with claim_bus("ixxat", "0", "seqrun run a.yaml") as claim:
        claim.set_socket("/some/where.sock")
        record = json.loads(claim.record_path.read_text())
    assert record["pid"] == os.getpid() and record["command"] == "seqrun run a.yaml"
    assert record["argv"] == sys.argv and record["socket"] == "/some/where.sock"
    assert before <= record["since"] <= time.time()
    assert not record["transient"]
    assert oct(os.stat(rundir).st_mode & 0o777) == "0o700"


def test_a_transient_holder_is_waited_for_a_holder_that_is_not_is_refused_at_once(rundir):
    brief = claim_bus("socketcan", "can0", "seqrun status", transient=True)
    import threading

    threading.Timer(0.3, brief.release).start()
    t0 = time.monotonic()
    with claim_bus("socketcan", "can0", "seqrun run"):
        waited = time.monotonic() - t0
    assert 0.25 < waited < 2.0
    with claim_bus("socketcan", "can0", "seqrun run"):
        t0 = time.monotonic()
        with pytest.raises(Refused):
            claim_bus("socketcan", "can0", "seqrun status", transient=True)
        assert time.monotonic() - t0 < 0.2
    # A transient holder that stays too long refuses as well, after the wait.
    with claim_bus("socketcan", "can0", "seqrun reset", transient=True):
        with pytest.raises(Refused, match=r"seqrun reset"):
            claim_bus("socketcan", "can0", "seqrun run", wait_s=0.1)


def test_a_killed_holder_leaves_no_stale_claim(rundir):
    code = ("import sys, time; from seqrun.service.bus_claim import claim_bus; "
            "c = claim_bus('socketcan', 'can0', 'seqrun run held.yaml'); "
            "print('held', flush=True); time.sleep(60)")
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(Refused, match=rf"pid {holder.pid} \(seqrun run held\.yaml\)"):
            claim_bus("socketcan", "can0", "seqrun run")
        holder.send_signal(signal.SIGKILL)
        holder.wait(timeout=10)
        # Its record is still on disk, but the kernel dropped its lock.
        assert read_holder("socketcan", "can0").pid == holder.pid
        with claim_bus("socketcan", "can0", "seqrun run") as claim:
            assert read_holder("socketcan", "can0").pid == os.getpid() == claim.holder().pid
    finally:
        if holder.poll() is None:
            holder.kill()


def test_runtime_dir_follows_xdg_else_tmp(monkeypatch, tmp_path):
    monkeypatch.delenv("SEQRUN_RUNTIME_DIR", raising=False)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    assert runtime_dir() == tmp_path / "seqrun"
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path / "missing"))
    assert runtime_dir().name == f"seqrun-{os.getuid()}"


def test_a_runtime_dir_of_someone_else_is_not_used(rundir):
    rundir.parent.mkdir(exist_ok=True)
    rundir.symlink_to(rundir.parent)   # a link planted where the directory should be
    from seqrun.errors import UserInputError

    with pytest.raises(UserInputError, match="not a directory of this user"):
        claim_bus("socketcan", "can0")


def test_command_line_reads_as_typed():
    assert command_line(["/x/seqrun/__main__.py", "run", "my file.yaml"]) == \
        "seqrun run 'my file.yaml'"


def test_a_holder_is_alive_only_while_its_own_process_runs(rundir):
    """A record outlives a killed holder; the system may give its pid to another process.
    The record's start time tells them apart (a reused pid is not the holder)."""
    from dataclasses import replace

    from seqrun.service.bus_claim import Holder, process_start

    other = subprocess.Popen(["sleep", "60"])
    try:
        started = process_start(other.pid)
        assert isinstance(started, int) and started != process_start(os.getpid())
        holder = Holder(pid=other.pid, command="seqrun run", since=time.time(),
                        started=started)
        assert holder.alive()
        assert not replace(holder, started=started - 1).alive()   # another process, same pid
        assert Holder.from_dict(json.loads(json.dumps(holder.as_dict()))) == holder
    finally:
        other.kill()
        other.wait()
    assert not holder.alive()
    with claim_bus("socketcan", "can0", "seqrun run") as claim:
        assert claim.holder().started == process_start(os.getpid())
        claim.describe_arm(campaign="/c", arm_id="A", reach=("-i", "socketcan", "-c", "can0"))
        assert read_holder("socketcan", "can0") == claim.holder()
        assert claim.holder().reach == ("-i", "socketcan", "-c", "can0")
