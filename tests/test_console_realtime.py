"""``seqrun console --rt-priority N``: the thread of the 100 Hz loop (the session's activity
thread) runs at SCHED_FIFO, and only it: the web server's threads, the status poll and the
threads the loop starts keep normal scheduling. Linux; needs the right to (CI runs as root)."""

from __future__ import annotations

import os
import threading

from consolekit import console_setup, wait_for

from seqrun.service.realtime import thread_policy, use_fifo


def policy_of(thread: threading.Thread) -> int:
    return os.sched_getscheduler(thread.native_id) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)


def test_only_the_loop_thread_runs_at_sched_fifo(tmp_path):
    setup = console_setup(tmp_path, loop_priority=7)
    session = setup.session
    try:
        session.poll_status()
        sub = session.subscribe(maxsize=100_000)
        # a run that waits at its confirm step: its thread is the loop's, alive meanwhile
        activity = session.run_sequence(setup.folder / "sequences" / "confirm_nudge.yaml")
        asked = wait_for(lambda: [e for e in sub.drain() if e.type == "confirm_requested"],
                         timeout=60)
        loop = next(t for t in threading.enumerate() if t.name == f"seqrun-run-{activity.id}")
        assert policy_of(loop) == os.SCHED_FIFO
        assert os.sched_getparam(loop.native_id).sched_priority == 7
        others = [t for t in threading.enumerate() if t is not loop and t.native_id]
        assert others and all(policy_of(t) == os.SCHED_OTHER for t in others), \
            [(t.name, policy_of(t)) for t in others]
        session.answer(asked[0].question_id, True)
        assert activity.wait(120).ok
    finally:
        setup.close()
    assert thread_policy() == (os.SCHED_OTHER, 0)  # the test's own thread: untouched


def test_threads_the_loop_starts_run_at_normal_priority():
    seen: list[tuple[int, int]] = []

    def loop() -> None:
        assert use_fifo(3) is None
        helper = threading.Thread(target=lambda: seen.append(thread_policy()))
        helper.start()
        helper.join()
        seen.append(thread_policy())

    t = threading.Thread(target=loop)
    t.start()
    t.join()
    assert seen == [(os.SCHED_OTHER, 0), (os.SCHED_FIFO, 3)]


def test_no_right_to_real_time_says_why_and_changes_nothing():
    out: list = []

    def loop() -> None:
        out.append(use_fifo(100))  # outside 1-99: refused by the kernel
        out.append(thread_policy())

    t = threading.Thread(target=loop)
    t.start()
    t.join()
    assert out[0] and out[1] == (os.SCHED_OTHER, 0)
