"""Garbage in reference cycles is collected while nothing moves, not in a control loop.

A full collection holds the interpreter for as long as it scans: after a report.html
(matplotlib's figures: ~70,000 objects in cycles) the next real-time run's loop lost
70-100 ms cycles to one. Both tests switch the automatic collector off, so that only an
explicit collection can free what they look at.
"""

from __future__ import annotations

import gc
import weakref
from collections.abc import Iterator
from pathlib import Path

import pytest

from projecttree import write_sequence
from seqrun.clock import RealClock, VirtualClock
from seqrun.service.connection import open_connection
from seqrun.service.runner import build_executor, write_html_report
from seqrun.sequence.loader import load_sequence
from simrun import run_on_sim


class _Cycle:
    me: _Cycle


@pytest.fixture
def no_automatic_collections() -> Iterator[None]:
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


def _old_garbage() -> weakref.ref:
    """An object in a reference cycle, dropped: nothing but a collection frees it."""
    obj = _Cycle()
    obj.me = obj
    return weakref.ref(obj)


@pytest.mark.parametrize("clock, collected", [(RealClock, True), (VirtualClock, False)])
def test_a_run_in_real_time_collects_before_its_first_frame(project: Path, arm, clock,
                                                            collected,
                                                            no_automatic_collections):
    """Real time: collected before the preflight's first frame. Virtual time (a dry run,
    where no loop has a deadline): left alone, the dry run stays cheap."""
    loaded = load_sequence(write_sequence(project, "  - wait: {seconds: 0.01}\n"))
    connection = open_connection(force_sim=True, clock=clock())
    freed_at_first_frame: list[bool] = []
    try:
        executor, client = build_executor(loaded, arm, connection)
        client.add_frame_listener(
            lambda msg: freed_at_first_frame.append(probe() is None)
            if not freed_at_first_frame else None)
        probe = _old_garbage()
        executor.run(loaded)
        client.close()
    finally:
        connection.close()
    assert freed_at_first_frame == [collected]


def test_drawing_a_report_leaves_no_garbage_for_the_next_run(tmp_path: Path,
                                                              no_automatic_collections):
    folder = run_on_sim("totem", tmp_path).outcome.log_dir
    gc.collect()
    assert write_html_report(folder) is None
    assert (folder / "report.html").is_file()
    assert gc.collect() < 1000   # without the collection after drawing: ~70,000
