"""``seqrun console`` in a campaign with several arms (issue 28): every arm served (or those
named with --arm-id), the first lines naming each arm, file and bus, STOP halting every
arm; on two built-in simulators and on two served simulated arms (as two ``seqrun sim
serve``)."""

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
from armsconsolekit import TWO_ARMS
from consolekit import project_tree
from projecttree import ROOT
from twoarmskit import halted, served_campaign, two_served

pytestmark = pytest.mark.slow  # a console process each


def env(tmp_path: Path) -> dict[str, str]:
    clean = {k: v for k, v in os.environ.items()
             if k not in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG")}
    return {**clean, "PYTHONPATH": str(ROOT), "HOME": str(tmp_path),
            "SEQRUN_STATE_DIR": str(tmp_path / "state")}


def start(folder: Path, tmp_path: Path, *options: str, stdin: str = ""
          ) -> tuple[subprocess.Popen, str, str, str]:
    """``seqrun console --port 0 OPTIONS`` in the campaign ``folder``: the process, what it
    printed up to its token, the URL (without the token) and the token."""
    proc = subprocess.Popen([sys.executable, "-m", "seqrun", "console", "--port", "0",
                             *options], cwd=folder, env=env(tmp_path), stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.write(stdin)
    proc.stdin.flush()
    lines: list[str] = []
    while True:
        line = proc.stdout.readline()
        if not line:
            proc.wait()
            raise AssertionError("seqrun console ended before printing its URL:\n"
                                 + "".join(lines))
        lines.append(line)
        found = re.search(r"(http://127\.0\.0\.1:\d+/)\?token=(\S+)", line)
        if found:
            return proc, "".join(lines), found.group(1), found.group(2)


def stop(proc: subprocess.Popen) -> str:
    proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


def get(url: str, token: str | None) -> tuple[int, dict]:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers),
                                    timeout=10) as r:
            return r.status, json.load(r)
    except urllib.error.HTTPError as exc:
        return exc.code, json.load(exc)


def halt(url: str) -> dict:
    request = urllib.request.Request(url + "api/v1/halt", method="POST", data=b"")
    with urllib.request.urlopen(request, timeout=30) as r:
        return json.load(r)


def campaign(tmp_path: Path, text: str = TWO_ARMS) -> Path:
    folder = project_tree(tmp_path / "campaign")
    (folder / "seqrun.toml").write_text(text)
    return folder


def test_the_console_serves_every_arm_and_stop_halts_both(tmp_path):
    folder = campaign(tmp_path)
    # (--zero-confirmed: every arm's word, checked per arm; issue 45: it was refused)
    proc, printed, url, token = start(folder, tmp_path, "--sim", "--zero-confirmed", "park")
    try:
        lines = printed.splitlines()
        # the first lines: each arm, its file and its bus
        heads = [l for l in lines if l.startswith(("arm A: arm ", "arm B: arm "))]
        assert len(heads) == 2, printed
        assert all("lwa3.yaml" in l and "SIMULATOR" in l for l in heads), printed
        assert "seqrun console of arms A, B" in printed
        code, arms = get(url + "api/v1/arms", token)
        assert code == 200 and [a["id"] for a in arms] == ["A", "B"]
        assert get(url + "api/v1/arms/B/status", token)[1]["simulator"] is True
        answer = halt(url)  # no token
        assert answer["halt_confirmed"] is True and set(answer["arms"]) == {"A", "B"}
    finally:
        out = stop(proc)
    assert proc.returncode == 130 and "Traceback" not in out, out


def test_arm_id_serves_the_named_arms_only_and_bad_options_are_one_line(tmp_path):
    folder = campaign(tmp_path)
    proc, printed, url, token = start(folder, tmp_path, "--sim", "--arm-id", "B")
    try:
        assert "arm B: arm " in printed and "arm A: arm " not in printed
        code, arms = get(url + "api/v1/arms", token)
        assert [a["id"] for a in arms] == ["B"]
        code, body = get(url + "api/v1/arms/A/status", token)
        assert code == 404 and "unknown arm 'A'" in body["error"]
    finally:
        stop(proc)
    for options, words in ((["--arm-id", "C"], "unknown arm 'C'"),
                           (["-i", "virtual", "-c", "x"], "not for a campaign with several"),
                           (["--zero-confirmed", "C=park"], "no arm 'C' here (arms A, B)")):
        run = subprocess.run([sys.executable, "-m", "seqrun", "console", "--sim", "--port", "0",
                              *options], cwd=folder, env=env(tmp_path), capture_output=True,
                             text=True, timeout=60)
        assert run.returncode == 2, (options, run.stdout, run.stderr)
        said = (run.stdout + run.stderr).strip().splitlines()
        assert len(said) == 1 and words in said[0] and "Traceback" not in said[0], said
    # one arm's --zero-confirmed that is not its zero: refused naming the arm
    run = subprocess.run([sys.executable, "-m", "seqrun", "console", "--sim", "--port", "0",
                          "--zero-confirmed", "A=park", "--zero-confirmed", "B=totem"],
                         cwd=folder, env=env(tmp_path), capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 2, run.stdout + run.stderr
    assert run.stderr.strip().splitlines()[-1].startswith(
        "error: arm B: --zero-confirmed totem: the zero reference in force is Park"), run.stderr


def test_two_served_arms_each_its_bus_and_zero_and_one_stop(tmp_path):
    first, second = two_served()
    try:
        folder = campaign(tmp_path, served_campaign(first, second))
        # where each arm was powered off, recorded per arm (its serials) as on the rig
        for server, pose in ((first, "park"), (second, "totem")):
            zero = subprocess.run(
                [sys.executable, "-m", "seqrun", "zero", "set", pose, "-i", "socketcand",
                 "-c", "can0", "--bus-kwargs", "host=127.0.0.1", "--bus-kwargs",
                 f"port={server.port}"], cwd=tmp_path, env=env(tmp_path), input="y\n",
                capture_output=True, text=True, timeout=60)
            assert zero.returncode == 0, zero.stdout + zero.stderr
        # after a power-on each arm's zero is confirmed in the terminal, one arm each
        proc, printed, url, token = start(folder, tmp_path, stdin="y\ny\n")
        try:
            # each arm's bus, told apart
            assert f"arm A: CAN interface 'socketcand' 127.0.0.1:{first.port} channel 'can0' " \
                   f"at 1000000 bit/s " \
                   f"(host=127.0.0.1, port={first.port})" in printed, printed
            assert f"port={second.port})" in printed, printed
            assert "arm A: " in printed and "arm B: " in printed
            code, arms = get(url + "api/v1/arms", token)
            assert [a["simulator"] for a in arms] == [False, False]
            status_b = get(url + "api/v1/arms/B/status", token)[1]
            # B powered on at Totem: its zero is its own (its serials), not A's
            assert status_b["zero_reference"] == "totem", status_b["zero_reference"]
            assert get(url + "api/v1/arms/A/status", token)[1]["zero_reference"] == "park"
            answer = halt(url)
            assert answer["halt_confirmed"] is True, answer
            assert halted(first) and halted(second)
        finally:
            out = stop(proc)
        assert "Traceback" not in out, out
    finally:
        first.shutdown()
        second.shutdown()
