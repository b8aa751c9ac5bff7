"""Which arm, on this machine (issue 43 item 4, issue 44 item 3), through the CLI beside
other seqrun processes: `halt` and `status` with no bus act on this campaign's arms only
and list a real arm driven from elsewhere with the command that reaches it; another
folder's built-in simulator never blocks a run; claims and the same-bus check key on the
server reached (`localhost` is `127.0.0.1`); a record left by a killed process whose pid
was reused blocks nothing; every line that names a socketcand bus says host:port."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from consolekit import console_process
from projecttree import ROOT, make_project
from twoarmskit import halted, quiet, served, two_arm_campaign, two_served_campaign
from zerostate import ZERO_CONFIRMED, serve_arm, socketcand_args, with_park_recorded

from seqrun.cli import app
from seqrun.service.bus_claim import Holder, read_holder
from seqrun.service.control_socket import ask_holder, live_owners

PLAIN_RUN = ("--yes", "--plain", "--no-report")


def seqrun(*args: str, cwd: Path, env: dict | None = None,
           timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "seqrun", *args], cwd=cwd,
                          env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})},
                          capture_output=True, text=True, timeout=timeout)


def wait_for(found, what: str, timeout: float = 90):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = found()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"{what}: not within {timeout} s")


def console_elsewhere(tmp_path: Path):
    """Another user's `seqrun console --sim`, started in a folder of its own:
    ``(process, its live holder)``."""
    proc, _ = console_process(tmp_path / "their-runs", "--project",
                              str(make_project(tmp_path / "theirs")))
    holder = wait_for(lambda: [h for h in live_owners() if h.pid == proc.pid],
                      "the other console's claim")[0]
    return proc, holder


def is_halted(holder: Holder) -> bool:
    reply = ask_holder(holder, "status")
    assert reply is not None and reply["ok"], reply
    return "HALTED" in json.dumps(reply["status"]["joints"])


# ------------------------------------------------------------------ another folder's sim
@pytest.mark.slow
def test_halt_and_status_of_a_two_arm_campaign_leave_another_folders_simulator_alone(
        tmp_path, monkeypatch):
    """The issue's reproduction: a two-arm campaign whose arms name no bus, another
    folder's `console --sim` live. `seqrun halt` halted it and said "Halt confirmed" for
    arm A; now it says no arm of this campaign is live (exit 2) and touches nothing."""
    theirs, holder = console_elsewhere(tmp_path)
    try:
        campaign = two_arm_campaign(tmp_path / "mine", monkeypatch)
        halt = seqrun("halt", cwd=campaign)
        assert halt.returncode == 2, halt.stdout + halt.stderr
        assert "Halt confirmed" not in halt.stdout + halt.stderr
        for arm in "AB":
            assert re.search(rf"no arm to halt: .* no seqrun run or console of arm {arm} of "
                             r"campaign \S+two-arms is live on this machine", halt.stderr), \
                halt.stderr
        status = seqrun("status", "--json", cwd=campaign)
        assert status.returncode == 2, status.stdout + status.stderr
        assert status.stdout == "" and "no arm to read" in status.stderr
        assert not is_halted(holder)
        # (the check above can fail: the same console, picked by its pid, is halted)
        by_pid = seqrun("halt", "--arm-id", "A", "--pid", str(theirs.pid), cwd=campaign)
        assert by_pid.returncode == 0, by_pid.stdout + by_pid.stderr
        assert is_halted(holder)
    finally:
        theirs.kill()
        theirs.wait()


@pytest.mark.slow
def test_status_and_halt_by_pid_of_a_two_arm_console_act_on_each_arm_once(tmp_path,
                                                                           monkeypatch):
    """A console of both arms holds one record per arm under one pid. `status --pid PID`
    saw both records for each arm ("... are live: pick one with --pid PID") and ended with
    "error: not confirmed"; `halt --pid PID` halted both arms for each arm. Now each arm is
    read (and halted) through its own record, and status ends cleanly."""
    campaign = two_arm_campaign(tmp_path / "mine", monkeypatch)
    console, _ = console_process(tmp_path / "runs", "--project", str(campaign))
    try:
        wait_for(lambda: len([h for h in live_owners() if h.pid == console.pid]) == 2,
                 "the console's two records")
        status = seqrun("status", "--pid", str(console.pid), "--json", cwd=campaign)
        assert status.returncode == 0, status.stdout + status.stderr
        assert status.stderr == ""
        lines = [json.loads(line) for line in status.stdout.splitlines()]
        assert [(line["arm"], line["from"]["pid"]) for line in lines] == [
            ("A", console.pid), ("B", console.pid)]
        table = seqrun("status", "--pid", str(console.pid), cwd=campaign)
        assert table.returncode == 0 and table.stderr == "", table.stdout + table.stderr
        assert table.stdout.rstrip().splitlines()[-1].startswith("end-effector")
        halt = seqrun("halt", "--pid", str(console.pid), cwd=campaign)
        assert halt.returncode == 0, halt.stdout + halt.stderr
        assert halt.stdout.count("Halt confirmed") == 2, halt.stdout
    finally:
        console.kill()
        console.wait()


def test_a_failing_arm_of_several_ends_status_with_not_read(tmp_path, monkeypatch):
    """With no arm of the campaign live, each arm's status says so, and the last line
    names the arms not read (it said "not confirmed", a halt's word)."""
    two_arm_campaign(tmp_path / "mine", monkeypatch)
    result = CliRunner().invoke(app, ["status"])
    assert result.exit_code == 2, result.output
    assert result.output.splitlines()[-1] == \
        "error: status not read for arms A, B (every arm was asked)"
    assert "not confirmed" not in result.output


@pytest.mark.slow
def test_the_readmes_first_command_works_beside_another_folders_simulator(tmp_path):
    theirs, _ = console_elsewhere(tmp_path)
    try:
        # (in real time, as the README has it: a --virtual-time run was never refused)
        run = seqrun("run", "sequences/opsafe.yaml", *PLAIN_RUN,
                     "--log-dir", str(tmp_path / "runs"), cwd=ROOT)
        assert run.returncode == 0, run.stdout + run.stderr
        assert "PASSED" in run.stdout
    finally:
        theirs.kill()
        theirs.wait()


# ------------------------------------------------------------------ a reused pid
def test_a_record_whose_pid_was_reused_blocks_nothing(tmp_path, monkeypatch,
                                                      private_runtime_dir):
    """A run on a real bus was killed (its record and socket file stay); the system gave
    its pid to another process. The record names this campaign and a real bus: were the
    pid taken for the holder, every run here would be refused."""
    project = make_project(tmp_path / "campaign", sequences=("startup.yaml",))
    quiet(tmp_path, monkeypatch)
    monkeypatch.chdir(project)
    other = subprocess.Popen(["sleep", "120"])
    try:
        started = int(Path(f"/proc/{other.pid}/stat").read_text().rpartition(")")[2].split()[19])
        socket_file = private_runtime_dir / "dead.sock"
        socket_file.write_text("")
        stale = {"pid": other.pid, "command": "seqrun run sequences/startup.yaml",
                 "since": time.time() - 60, "socket": str(socket_file), "transient": False,
                 "bus": "socketcand:127.0.0.1:1/can0", "started": started - 1,
                 "campaign": str(project.resolve()), "arm_id": None,
                 "reach": ["-i", "socketcand", "-c", "can0", "--bus-kwargs", "host=127.0.0.1",
                           "port=1"]}
        (private_runtime_dir / "socketcand-stale.json").write_text(json.dumps(stale))
        run = CliRunner().invoke(app, ["run", "sequences/startup.yaml", *PLAIN_RUN,
                                       "--virtual-time", "--log-dir", "runs"])
        assert run.exit_code == 0, run.output
        halt = CliRunner().invoke(app, ["halt"])
        assert halt.exit_code == 2, halt.output
        assert "no arm to halt" in halt.output and str(other.pid) not in halt.output
    finally:
        other.kill()
        other.wait()


# ------------------------------------------------------------------ the server, not its name
def test_two_arms_on_one_server_are_refused_however_its_host_is_spelt(tmp_path,
                                                                      monkeypatch):
    campaign = two_arm_campaign(tmp_path, monkeypatch)
    (campaign / "seqrun.toml").write_text(
        '[arms.A]\nbus = { interface = "socketcand", channel = "can0", '
        'kwargs = { host = "localhost", port = 29999 } }\n\n'
        '[arms.B]\nbus = { interface = "socketcand", channel = "can0", '
        'kwargs = { host = "127.0.0.1", port = 29999 } }\n'
        'base = { position_mm = [0, 900, 0], rpy_deg = [0, 0, 180] }\n')
    result = CliRunner().invoke(app, ["validate", "sequences/short.yaml"])
    assert result.exit_code == 2, result.output
    assert result.output.strip().splitlines() == [
        "error: seqrun.toml: arms A and B are on the same bus "
        "(socketcand:127.0.0.1:29999/can0, however its host is spelt): one controller per "
        "bus; give each arm a bus of its own"]


@pytest.mark.slow
def test_a_run_on_a_served_arm_is_found_by_its_server_and_named_from_elsewhere(tmp_path):
    """A run drives `sim serve` as host=127.0.0.1. `limits set` with host=localhost is
    refused (one controller per bus). `seqrun halt` in a folder that names no bus neither
    halts it nor says it did: it lists the run with the command that reaches it (exit 2);
    that command halts it."""
    server, port, env = serve_arm(tmp_path, cwd=ROOT)
    env = {**env, "SEQRUN_RESPONSE_TIMEOUT_MS": "200", "PYTHONUNBUFFERED": "1"}
    run = subprocess.Popen(
        [sys.executable, "-m", "seqrun", "run", "sequences/opsafe.yaml", *PLAIN_RUN,
         "--speed", "0.25", "--log-dir", str(tmp_path / "run"), *socketcand_args(port),
         *ZERO_CONFIRMED], cwd=ROOT, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    try:
        key = ("socketcand", f"127.0.0.1:{port}/can0")
        wait_for(lambda: (read_holder(*key) or Holder(0, "", 0)).socket, "the run's claim")
        limits = seqrun("limits", "set", "-i", "socketcand", "--bus-kwargs", "host=localhost",
                        f"port={port}", cwd=ROOT, env=env)
        assert limits.returncode == 2, limits.stdout + limits.stderr
        assert f"socketcand:127.0.0.1:{port}/can0 is held by pid {run.pid}" in limits.stderr
        assert "wrote" not in limits.stdout.lower()

        elsewhere = make_project(tmp_path / "elsewhere")
        halt = seqrun("halt", cwd=elsewhere, env=env)
        assert halt.returncode == 2, halt.stdout + halt.stderr
        assert "Halt confirmed" not in halt.stdout + halt.stderr
        command = f"seqrun halt -i socketcand -c can0 --bus-kwargs host=127.0.0.1 port={port}"
        listed = [line for line in halt.stderr.splitlines() if f"pid {run.pid}" in line]
        assert len(listed) == 1 and listed[0].endswith(": " + command), halt.stderr
        assert f"socketcand:127.0.0.1:{port}/can0" in listed[0]
        status = seqrun("status", cwd=elsewhere, env=env)
        assert status.returncode == 2 and f"pid {run.pid}" in status.stderr
        assert run.poll() is None   # still running, nobody halted it

        reached = seqrun(*shlex.split(command)[1:], cwd=elsewhere, env=env)
        assert reached.returncode == 0, reached.stdout + reached.stderr
        assert f"read back by the running seqrun (pid {run.pid}" in reached.stdout
        out, _ = run.communicate(timeout=60)
        assert run.returncode == 3, out
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
        server.kill()
        server.wait()


# ------------------------------------------------------------------ bus lines (issue 44.3)
def test_every_line_naming_a_served_bus_says_its_host_and_port(tmp_path, monkeypatch):
    with two_served_campaign(tmp_path, monkeypatch) as arms:
        ports = {a: server.port for a, server in arms.items()}
        for command in (["status"], ["halt"]):
            result = CliRunner().invoke(app, command)
            assert result.exit_code == 0, result.output
            arm, named = None, []
            for line in result.output.splitlines():   # each arm's lines follow its headline
                headline = re.match(r"arm (\w+): ", line)
                arm = headline.group(1) if headline else arm
                if "socketcand" in line:
                    assert f"127.0.0.1:{ports[arm]}" in line, line
                    named.append(arm)
            assert set(named) == {"A", "B"}, result.output
            assert halted(arms["A"]) == halted(arms["B"]) == (command == ["halt"])


# ------------------------------------------------------------------ one arm, two endpoints
@pytest.mark.slow
def test_one_arm_reached_over_two_endpoints_has_one_controller(tmp_path):
    """Two servers whose modules report the same serial numbers are one arm reached two
    ways (its adapter and a socketcand bridge, say): a console on one (it holds the arm
    until it is ended), and a run on the other is refused once it has read the serials,
    before it resets or homes."""
    first, second = served(5_300_000, "park"), served(5_300_000, "park")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "SEQRUN_RESPONSE_TIMEOUT_MS": "200",
           "PYTHONUNBUFFERED": "1"}
    env = with_park_recorded(env, tmp_path, first.port, cwd=ROOT)   # (one record: one arm)
    run = subprocess.Popen(
        [sys.executable, "-m", "seqrun", "console", "--port", "0", "--log-dir",
         str(tmp_path / "console"), *socketcand_args(first.port), *ZERO_CONFIRMED],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        key = ("socketcand", f"127.0.0.1:{first.port}/can0")
        wait_for(lambda: (read_holder(*key) or Holder(0, "", 0)).serials,
                 "the console's serials")
        other = seqrun("run", "sequences/opsafe.yaml", *PLAIN_RUN, "--log-dir",
                       str(tmp_path / "other"), *socketcand_args(second.port),
                       *ZERO_CONFIRMED, cwd=ROOT, env=env)
        assert other.returncode == 2, other.stdout + other.stderr
        assert re.search(rf"the arm with serials 1:5300001, .* is driven by pid {run.pid} "
                         rf"\(seqrun console .*\) since .* on socketcand:127\.0\.0\.1:"
                         rf"{first.port}/can0: one controller per arm", other.stderr), \
            other.stderr
        # nothing was sent to make it move: its modules are still not homed
        from seqrun.powercube.protocol import StateFlag

        states = second.network.arm.states().values()
        assert not any(StateFlag(s) & StateFlag.HOME_OK for s in states)
        assert run.poll() is None
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
        first.shutdown()
        second.shutdown()
