"""A process that runs one sequence after another (the console, a soak, tests through the
CLI in process) is left by each run as it was found: no memory kept for the runs before,
no signal handler of the run left installed.

The memory figures themselves (RSS per run, per virtual hour) are measured by
bench/rss_probe.py and bench/soak.py, not here.
"""

from __future__ import annotations

import ctypes
import gc
import signal
import weakref

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ARM_FILE, ROOT
from seqrun.arm.cartesian import solver_for
from seqrun.arm.description import load_arm
from seqrun.cli.app import app

SIGNALS = [getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
           if hasattr(signal, name)]


class _Mallinfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]


def _glibc():
    libc = ctypes.CDLL(None)
    if not hasattr(libc, "gnu_get_libc_version") or not hasattr(libc, "mallinfo2"):
        return None
    libc.mallinfo2.restype = _Mallinfo2
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    return libc


def _run(tmp_path, *args: str):
    return CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "park.yaml"),
                                    "--virtual-time", "--yes", "--plain",
                                    "--log-dir", str(tmp_path / "run"), *args])


@pytest.mark.skipif(_glibc() is None, reason="glibc's malloc parameters (this is glibc's "
                                              "behaviour; other C libraries differ)")
def test_after_a_run_a_large_block_is_mapped_on_its_own_not_kept_in_an_arena(tmp_path):
    """glibc raises its mmap threshold to the size of each large block freed, after which
    blocks of that size stay in the arenas when freed (resident, fragmenting them: the
    soak's growing RSS). A run fixes the threshold, so after a larger block is freed, a
    block too large for any free chunk the arenas hold is still mapped on its own (and
    unmapped when freed) instead of growing an arena."""
    libc = _glibc()
    result = _run(tmp_path)
    assert result.exit_code == 0, result.output
    # More than all the free bytes the arenas keep: no free chunk can serve it, only a
    # mapping of its own or a grown arena (a block that fits a free chunk is served from
    # it whatever the threshold; how many there are depends on what ran before).
    size = libc.mallinfo2().fordblks + (1 << 20)
    larger = size + (1 << 20)
    assert larger <= 32 << 20, f"the arenas keep {size >> 20} MiB free"  # glibc's cap
    libc.free(libc.malloc(larger))  # with a sliding threshold: now above ``size``
    before = libc.mallinfo2()
    block = libc.malloc(size)
    try:
        during = libc.mallinfo2()
    finally:
        libc.free(block)
    assert during.hblks == before.hblks + 1
    assert during.hblkhd >= before.hblkhd + size


def test_the_ik_solvers_of_the_arms_of_earlier_runs_are_let_go():
    """Each run loads its arm afresh; the IK solvers cached for it (which keep the arm)
    must not pile up for the life of the process."""
    first = load_arm(ARM_FILE)
    solver_for(first, None)
    gone = weakref.ref(first)
    del first
    for _ in range(40):  # the runs after
        arm = load_arm(ARM_FILE)
        solver_for(arm, None)
        solver_for(arm, None, tracking=True)
    gc.collect()
    assert gone() is None


def test_a_run_in_process_leaves_the_signal_handlers_as_it_found_them(tmp_path):
    """The run's handlers (SIGTERM halts the run, etc.) are the run's: after it the
    process's own are back, for a clean run and a faulted one alike."""
    before = {s: signal.getsignal(s) for s in SIGNALS}
    clean = _run(tmp_path)
    assert clean.exit_code == 0, clean.output
    assert {s: signal.getsignal(s) for s in SIGNALS} == before
    faulted = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"),
                                       "--virtual-time", "--yes", "--plain",
                                       "--sim-fault", "4:tow_error@3",
                                       "--log-dir", str(tmp_path / "faulted")])
    assert faulted.exit_code == 3, faulted.output
    assert {s: signal.getsignal(s) for s in SIGNALS} == before
