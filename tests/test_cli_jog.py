"""``seqrun jog JOINT VELOCITY --for S``: the console's jog from a terminal, in velocity
mode by default, never open-ended, refused in one line when the arm is not homed."""

from __future__ import annotations

import re
import subprocess
import sys

from projecttree import ARM_FILE

SEQRUN = [sys.executable, "-m", "seqrun"]
# (a generous simulated watchdog: these tests are about the command, not a loaded host's
# timing; tests/test_jog_velocity.py holds the watchdog's bound at virtual time)
HOMED = ["--sim", "--bus-kwargs", "home_ok_at_power_on=true", "--bus-kwargs",
         "watchdog_timeout=0.5", "--arm", str(ARM_FILE)]


def seqrun(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*SEQRUN, *args], capture_output=True, text=True, timeout=120)


def test_a_velocity_jog_from_the_terminal_moves_then_stops(tmp_path):
    done = seqrun("jog", "j1", "-8", "--for", "0.4", *HOMED)
    assert done.returncode == 0, done.stderr
    assert "jog j1 at -8 deg/s for 0.4 s (velocity mode)" in done.stdout
    moved = float(re.search(r"j1 at (-?[\d.]+)°", done.stdout).group(1))
    assert -4.0 < moved < -0.5  # the commanded direction, about 8 deg/s for 0.4 s


def test_a_jog_on_an_arm_not_homed_is_one_line_and_moves_nothing():
    done = seqrun("jog", "j1", "5", "--for", "0.4", "--sim", "--arm", str(ARM_FILE))
    assert done.returncode == 2
    assert done.stderr.strip() == "error: jog: the modules are not homed; Arm and Home first"


def test_a_jog_is_never_open_ended():
    done = seqrun("jog", "j1", "5", "--for", "60", *HOMED)
    assert done.returncode == 2 and "--for" in done.stderr
    done = seqrun("jog", "j1", "50", "--for", "1", *HOMED)
    assert done.returncode == 2 and "above its limit" in done.stderr


def _thread_policies(pid: int) -> set[tuple[int, int]]:
    """(scheduling policy, real-time priority) of every thread of ``pid`` (fields 41 and
    40 of /proc/PID/task/TID/stat)."""
    from pathlib import Path

    found = set()
    for stat in Path(f"/proc/{pid}/task").glob("*/stat"):
        try:
            fields = stat.read_text().rpartition(")")[2].split()
        except OSError:
            continue   # a thread that ended meanwhile
        found.add((int(fields[38]), int(fields[37])))
    return found


def test_a_jog_with_rt_priority_runs_its_loop_at_sched_fifo(tmp_path):
    """`seqrun jog --rt-priority N` as `run` and `console` have it: the jog's loop thread
    at SCHED_FIFO N, the others at SCHED_RR 1 (a busy host otherwise delays the refresh of
    the modules' watchdog: bench/bench_jog.py)."""
    import os
    import time

    jog = subprocess.Popen([*SEQRUN, "jog", "j1", "5", "--for", "3", "--rt-priority", "7",
                            *HOMED], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    seen: set[tuple[int, int]] = set()
    try:
        deadline = time.monotonic() + 60
        while jog.poll() is None and time.monotonic() < deadline:
            seen |= _thread_policies(jog.pid)
            if (os.SCHED_FIFO, 7) in seen:
                break
            time.sleep(0.02)
        out, err = jog.communicate(timeout=60)
    finally:
        if jog.poll() is None:
            jog.kill()
            jog.wait()
    assert jog.returncode == 0, err
    assert "real-time scheduling: the control loop at SCHED_FIFO priority 7, the jog's " \
           "other threads at SCHED_RR 1" in out
    assert (os.SCHED_FIFO, 7) in seen and (os.SCHED_RR, 1) in seen, seen
