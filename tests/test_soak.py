"""Ten virtual minutes of the soak (``bench/soak.py``; its README figures are eight hours):
random valid sequences and random faults of every kind through the real CLI, one process.

Every fault that happened ends in a Halt on the bus (or is one no runner can see, and the
run passes); no run without a fault fails; the process ends with the open files and
threads it had before its first run (after the warm-up), and its memory does not grow with
the runs.
"""

from __future__ import annotations

import sys

import pytest

from projecttree import ROOT
from seqrun.sim.faults import FAULT_KINDS

sys.path.insert(0, str(ROOT / "bench"))

import soak  # noqa: E402


@pytest.mark.slow  # ~10 virtual minutes: a few minutes of wall time
def test_ten_virtual_minutes_of_random_runs_and_faults():
    lines: list[str] = []
    result = soak.soak(600, seed=29, moves=(3, 10), progress=lines.append)
    log = "\n".join(lines)
    assert result.virtual_s >= 600 and result.runs >= 10, log
    assert result.missed_halts == 0, result.wrong
    assert result.spurious_faults == 0, result.wrong
    # Every kind happened at least once, and every fault that happened is accounted for.
    happened = {kind for kind, outcomes in result.kinds.items()
                if kind != "none" and set(outcomes) - {"clean"}}
    assert happened == set(FAULT_KINDS), (result.kinds, log)
    assert result.faults_injected == (result.faults_ended_in_halt + result.faults_unobservable
                                      + result.faults_unseen_late), result.kinds
    assert result.faults_ended_in_halt >= len(FAULT_KINDS) - 1, result.kinds
    assert result.clean_runs >= 1, result.kinds
    # Nothing left open or running by the runs.
    assert result.open_files[1] == result.open_files[0]
    assert result.threads[1] == result.threads[0]
    assert result.os_threads[1] == result.os_threads[0]
    # The resident set after each run does not grow with the runs: once the allocator has
    # settled (~20 MB of arenas and caches over the first ten runs or so), the last third
    # of the runs never rises above the middle third's peak by more than a few MB.
    # (Comparing the last run with the second measured the settling: 19 MB with this
    # round's code and the last round's alike.)
    rss = [kb for _, kb in result.rss_kb]
    third = len(rss) // 3
    middle, last = rss[third:2 * third], rss[2 * third:]
    assert max(last) - max(middle) < 6 * 1024, (rss, log)


def _shard(seed: int, runs: int, halts: int, latency: float, rss_mb: tuple[int, int]) -> dict:
    return {"seed": seed, "hours": 4.0, "virtual_s": 3600.0 * runs / 10, "wall_s": 60.0 * seed,
            "runs": runs, "faults_injected": halts + 1, "faults_ended_in_halt": halts,
            "faults_unobservable": 1, "faults_unseen_late": 0, "faults_after_the_end": 2,
            "missed_halts": 0, "spurious_faults": 0, "clean_runs": runs - halts - 1,
            "kinds": {"tow_error": {"halted": halts}, "none": {"clean": runs - halts - 1}},
            "halt_latency_max_s": {"tow_error": latency}, "wrong": [],
            "rss_kb": [(0.1, rss_mb[0] * 1024), (0.2, rss_mb[1] * 1024)],
            "rss_slope_kb_per_h": 10.0 * seed, "open_files": (5, 5), "threads": (1, 1),
            "os_threads": (2, 2), "machine": {}, "load_avg_at_end": (1.0, 1.0, 1.0)}


def test_soaks_side_by_side_add_up_and_keep_memory_per_process():
    both = soak.combine([_shard(1, 10, 4, 0.05, (120, 130)), _shard(2, 20, 9, 0.07, (125, 128))])
    assert both["runs"] == 30 and both["virtual_s"] == 3600.0 * 3
    assert both["faults_ended_in_halt"] == 13 and both["faults_injected"] == 15
    assert both["kinds"] == {"tow_error": {"halted": 13}, "none": {"clean": 15}}
    assert both["halt_latency_max_s"] == {"tow_error": 0.07}
    assert both["wall_s"] == 120.0   # side by side: the longer one, not the sum
    assert [s["rss_slope_kb_per_h"] for s in both["shards"]] == [10.0, 20.0]
    assert [s["rss_mb_first_last"] for s in both["shards"]] == [[120, 130], [125, 128]]


def test_the_rss_after_the_first_hour_is_fitted_apart_and_read_hour_by_hour():
    """Growth that stops after the first hour (the allocator settling): the slope over
    every run says it grew, the slope after the first hour that it no longer does."""
    rss = [(0.1, 100 * 1024), (0.5, 120 * 1024), (0.9, 130 * 1024), (1.2, 131 * 1024),
           (1.8, 130 * 1024), (2.5, 131 * 1024), (2.9, 130 * 1024)]
    shard = _shard(1, 10, 4, 0.05, (100, 130)) | {"rss_kb": rss}
    (one,) = soak.combine([shard])["shards"]
    assert one["rss_mb_by_hour"] == [130, 130]
    assert abs(one["rss_slope_after_1h_kb_per_h"]) < 0.5 * 1024
    assert soak.slope(rss) > 2 * 1024


@pytest.mark.slow  # the warm-up and a run or two: under a minute on an idle host
def test_sigterm_ends_the_soak_after_the_run_under_way():
    """SIGTERM ends the soak (the run it lands in halts, exit 130, as ``seqrun run``
    does): it used to go on with the next run after each one, and only SIGKILL ended it."""
    import os
    import signal
    import threading

    got: list[int] = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: got.append(signum))
    timers: list[threading.Timer] = []

    def progress(line: str) -> None:
        if not timers:  # after the first run: during the second or between runs
            timers.append(threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGTERM)))
            timers[0].start()

    try:
        result = soak.soak(300, seed=3, moves=(1, 2), progress=progress)
        timers[0].join()
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert result.stopped_by is not None
    assert result.runs <= 2 and result.virtual_s < 300
    assert got == []  # the soak's, not the caller's


def test_a_sigterm_a_run_took_after_its_loop_ended_still_ends_the_soak():
    """A SIGTERM that lands while a run writes its report goes to the run's handler, which
    asks a control loop that has already ended: the run's exit code does not show it, and
    the soak went on. The soak reads it from Python's wake-up descriptor instead."""
    import os
    import signal

    with soak.StopSignals() as stop:
        assert stop.came_during_run() is None
        swallowed: list[int] = []
        soaks = signal.signal(signal.SIGTERM, lambda signum, frame: swallowed.append(signum))
        try:  # the run's handler, as seqrun.cli.interrupts installs it
            os.kill(os.getpid(), signal.SIGTERM)
        finally:
            signal.signal(signal.SIGTERM, soaks)
        assert swallowed == [signal.SIGTERM] and stop.received is None
        assert stop.came_during_run() == "SIGTERM"
        assert stop.came_during_run() is None   # read once
