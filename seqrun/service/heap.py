"""The C heap of a process that runs one sequence after another (the console, a soak, a
campaign): what each run frees goes back to the system instead of staying resident.

glibc's malloc serves a block of 128 KiB or more with its own ``mmap`` and unmaps it when
it is freed, but the threshold slides: each time such a block is freed, the threshold rises
to its size (up to 32 MiB), and the heap top an arena keeps untrimmed rises to twice that
(``mallopt(3)``, M_MMAP_THRESHOLD). A run frees blocks of a few MiB (the report's numpy
arrays, the MCAP writer's ~1 MiB chunk buffer), so from then on blocks of that size come
from the arenas. There they stay: an arena gives memory back only from its top, and a
thread's arena (the MCAP writer, the event listeners: new threads each run, each given
whichever arena is free) keeps its top resident below the raised trim threshold, which
``malloc_trim`` does not touch either. Each arena in turn grows to what the MCAP writer
needed, and the holes the report's arrays leave in the main heap add up. Measured with
``bench/rss_probe.py`` (bench/README.md, "Memory of a process that runs run after run").

A fixed threshold (the same 128 KiB glibc starts with) keeps large blocks out of the
arenas for the life of the process: each is mapped when allocated and unmapped when freed.
The cost is a system call and fresh pages per large block, negligible beside a run.
An operator's own setting (``MALLOC_MMAP_THRESHOLD_`` or ``GLIBC_TUNABLES``) is left alone,
as is a C library that is not glibc.
"""

from __future__ import annotations

import ctypes
import os
from typing import Any

#: <malloc.h>'s parameter number for mallopt.
M_MMAP_THRESHOLD = -3
#: Blocks of this size and larger are mapped one each (glibc's initial threshold).
LARGE_BLOCK_BYTES = 128 * 1024


def _glibc() -> Any:
    """The process's C library if it is glibc (None otherwise)."""
    global _libc
    if _libc is None:
        try:
            libc = ctypes.CDLL(None)
            libc.gnu_get_libc_version  # noqa: B018 - only glibc has it
            _libc = libc
        except (OSError, AttributeError):
            _libc = False
    return _libc or None


_libc: Any = None
_large_blocks_mapped = False


def keep_large_blocks_out_of_arenas() -> None:
    """Fix glibc's mmap threshold at 128 KiB for this process (once; see the module's
    docstring), unless the environment sets malloc's parameters itself."""
    global _large_blocks_mapped
    if _large_blocks_mapped:
        return
    _large_blocks_mapped = True
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or "GLIBC_TUNABLES" in os.environ:
        return
    libc = _glibc()
    if libc is not None:
        libc.mallopt(M_MMAP_THRESHOLD, LARGE_BLOCK_BYTES)


def return_freed_memory() -> None:
    """Give malloc's free pages back to the system (glibc's ``malloc_trim``: whole free
    pages inside every arena, and the main heap's top; nothing on another C library).
    Freed memory otherwise stays with the process in fragments: a process
    that runs one sequence after another (the console, a soak) would keep the resident
    set of its largest run so far plus its fragments instead of one run's."""
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)
