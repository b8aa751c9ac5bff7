"""``seqrun run --rt-priority N`` schedules as the console does (seqrun/service/realtime.py):
the loop's thread at SCHED_FIFO N, every thread already running at SCHED_RR 1, so that a
thread holding the interpreter lock is never kept off the CPU by ordinary processes while
the loop waits for it (with only the loop at FIFO, the modules' watchdog tripped in 2 of
10 runs of bench/bench_load_faults.py with both cores busy)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

PROBE = r"""
import json, os, sys, threading
from rich.console import Console
from seqrun.cli.run import use_realtime

ready, done = threading.Event(), threading.Event()
other = {}
def control_socket():  # a thread started before the run switched to real time
    other["tid"] = threading.get_native_id()
    ready.set()
    done.wait()
t = threading.Thread(target=control_socket)
t.start()
ready.wait()
use_realtime(Console(file=sys.stderr), 5)
mine = threading.get_native_id()
print(json.dumps({
    "loop": [os.sched_getscheduler(mine), os.sched_getparam(mine).sched_priority],
    "other": [os.sched_getscheduler(other["tid"]), os.sched_getparam(other["tid"]).sched_priority],
    "switch": sys.getswitchinterval()}))
done.set()
t.join()
"""


def _may_use_fifo() -> bool:
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, *before)
        return True
    except (OSError, AttributeError):
        return False


def test_rt_priority_puts_the_loop_at_fifo_and_the_other_threads_at_round_robin():
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                          timeout=60, check=False)
    if not _may_use_fifo():  # no right to: one warning line, nothing changed
        assert done.returncode == 0 and "real-time scheduling not available" in done.stderr
        assert json.loads(done.stdout)["loop"][0] == os.SCHED_OTHER
        return
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    assert got["loop"] == [os.SCHED_FIFO, 5]
    assert got["other"] == [os.SCHED_RR, 1]
    assert got["switch"] == pytest.approx(0.001)
