"""A process that runs one sequence after another (the console, a soak, tests through the
CLI in process) is left by each run as it was found: no memory kept for the runs before,
no signal handler of the run left installed.

The memory figures themselves (RSS per run, per virtual hour) are measured by
bench/rss_probe.py and bench/soak.py, not here.
"""

from __future__ import annotations

import ctypes
import gc
import json
import signal
import subprocess
import sys
import weakref
from pathlib import Path

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


#: In a process of its own (a long test process's heap holds free chunks of any size, left
#: by the tests before; a block that fits one is served from it whatever the threshold):
#: a run, then a large block freed, then a block larger than every free byte the arenas
#: keep, so that only a mapping of its own or a grown arena can serve it.
_LARGE_BLOCK_AFTER_A_RUN = """
import json, sys, tempfile
sys.path.insert(0, sys.argv[1])
from test_run_after_run import _glibc, _run
from pathlib import Path
libc = _glibc()
result = _run(Path(tempfile.mkdtemp()))
assert result.exit_code == 0, result.output
size = libc.mallinfo2().fordblks + (1 << 20)
libc.free(libc.malloc(size + (1 << 20)))  # with a sliding threshold: now above size
before = libc.mallinfo2()
block = libc.malloc(size)
during = libc.mallinfo2()
libc.free(block)
print(json.dumps({"size": size, "mapped_blocks": [before.hblks, during.hblks],
                  "mapped_bytes": [before.hblkhd, during.hblkhd]}))
"""


@pytest.mark.skipif(_glibc() is None, reason="glibc's malloc parameters (this is glibc's "
                                              "behaviour; other C libraries differ)")
def test_after_a_run_a_large_block_is_mapped_on_its_own_not_kept_in_an_arena():
    """glibc raises its mmap threshold to the size of each large block freed, after which
    blocks of that size stay in the arenas when freed (resident, fragmenting them: the
    soak's growing RSS). A run fixes the threshold, so after a larger block is freed a
    large block is still mapped on its own (and unmapped when freed)."""
    out = subprocess.run([sys.executable, "-c", _LARGE_BLOCK_AFTER_A_RUN,
                          str(Path(__file__).parent)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.splitlines()[-1])
    assert got["size"] < 31 << 20  # below glibc's cap on the sliding threshold (32 MiB)
    before, during = got["mapped_blocks"]
    assert during == before + 1
    assert got["mapped_bytes"][1] >= got["mapped_bytes"][0] + got["size"]


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
