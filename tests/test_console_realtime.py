"""``seqrun console --rt-priority N``: the thread of the 100 Hz loop (the session's activity
thread) runs at SCHED_FIFO N; the console's other threads at SCHED_RR 1, below it and above
every normal process, so that none of them is kept off the CPU by a busy browser while it
holds the interpreter lock the loop waits for. Linux; needs the right to (CI runs as root)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

from consolekit import console_setup, wait_for
from projecttree import ROOT

from seqrun.service.realtime import SWITCH_INTERVAL_S, thread_policy, use_fifo


def policy_of(thread: threading.Thread) -> int:
    return os.sched_getscheduler(thread.native_id)


def test_the_loop_thread_runs_at_sched_fifo_and_the_session_s_others_do_not(tmp_path):
    setup = console_setup(tmp_path, loop_priority=7)
    session = setup.session
    try:
        session.poll_status()
        sub = session.subscribe(maxsize=100_000)
        # a run that waits at its confirm step: its thread is the loop's, alive meanwhile
        activity = session.run_sequence(setup.folder / "sequences" / "confirm_nudge.yaml")
        asked = wait_for(lambda: [e for e in sub.drain() if e.type == "confirm_requested"],
                         timeout=60)
        threads = {t.name: t for t in threading.enumerate()}
        loop = threads[f"seqrun-run-{activity.id}"]
        assert policy_of(loop) == os.SCHED_FIFO
        assert os.sched_getparam(loop.native_id).sched_priority == 7
        for name in ("seqrun-status-poll", "seqrun-listener-session status", "MainThread"):
            assert policy_of(threads[name]) == os.SCHED_OTHER, name
        session.answer(asked[0].question_id, True)
        assert activity.wait(120).ok
    finally:
        setup.close()
    assert thread_policy() == (os.SCHED_OTHER, 0)  # the test's own thread: untouched


PROCESS = """
import threading, os
from seqrun.service.realtime import use_round_robin, use_fifo, thread_policy
seen = {}
early = threading.Event()
def wait_then_report():
    early.wait()
    seen["started before"] = thread_policy()
before = threading.Thread(target=wait_then_report)
before.start()
assert use_round_robin() is None
early.set()
before.join()
after = threading.Thread(target=lambda: seen.setdefault("started after", thread_policy()))
after.start(); after.join()
def loop():
    assert use_fifo(9) is None
    seen["loop"] = thread_policy()
    child = threading.Thread(target=lambda: seen.setdefault("started by the loop",
                                                            thread_policy()))
    child.start(); child.join()
t = threading.Thread(target=loop); t.start(); t.join()
seen["main"] = thread_policy()
print(seen)
"""


def test_every_other_thread_of_the_process_runs_round_robin_below_the_loop():
    out = subprocess.run([sys.executable, "-c", PROCESS], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60)
    assert out.returncode == 0, out.stderr
    rr, fifo = (os.SCHED_RR, 1), (os.SCHED_FIFO, 9)
    assert eval(out.stdout) == {"started before": rr, "started after": rr, "main": rr,
                                "loop": fifo, "started by the loop": fifo}


def test_no_right_to_real_time_says_why_and_changes_nothing():
    out: list = []

    def loop() -> None:
        out.append(use_fifo(100))  # outside 1-99: refused by the kernel
        out.append(thread_policy())

    t = threading.Thread(target=loop)
    t.start()
    t.join()
    assert out[0] and out[1] == (os.SCHED_OTHER, 0)


def test_a_thread_holding_the_interpreter_lock_hands_it_over_within_a_millisecond():
    # (in a process of its own: the switch interval is the whole interpreter's)
    code = ("import sys; from seqrun.service.realtime import hand_over_the_lock_often as h; "
            "before = sys.getswitchinterval(); h(); print(repr((before, sys.getswitchinterval())))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60)
    assert out.returncode == 0, out.stderr
    before, after = eval(out.stdout)
    assert before == 0.005 and after == SWITCH_INTERVAL_S == 0.001


def test_the_objects_made_before_serving_are_out_of_the_collectors_view():
    code = ("import gc; from seqrun.service.realtime import "
            "keep_long_lived_objects_out_of_collections as keep; "
            "import seqrun.console.app; before = gc.get_freeze_count(); n = keep(); "
            "print(repr((before, n, gc.get_freeze_count())))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60)
    assert out.returncode == 0, out.stderr
    before, returned, after = eval(out.stdout)
    assert before == 0 and returned == after > 10_000  # the web stack's objects, at least
