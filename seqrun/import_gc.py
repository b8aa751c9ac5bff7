"""Imports without cyclic garbage collection; what they made is kept out of later ones.

Start-up makes ~45,000 long-lived objects (modules, classes, functions, pydantic's
schemas and validators) and almost no garbage. The cyclic collector, run every 700
allocations, walked them again and again while they were made, and every later
collection of the older generations (and the one at exit) walks them again: ~0.1 G
instructions of ``seqrun validate`` that find nothing to free.

:func:`install` wraps importlib's loading of a module not yet imported: during an
outermost import the collector is off; when it has succeeded, :func:`gc.freeze` moves every
object then alive out of the collector's view (as the console does once it serves,
:func:`seqrun.service.realtime.keep_long_lived_objects_out_of_collections`) and the
collector is on again. Bounded, unlike the collector off for the whole process (rejected
earlier): a module is imported once, so there is at most one pause and one freeze per module;
garbage alive at a freeze (cycles not yet collected) stays, at most what one round of the
collector would have found, once per module. A failed import (a probe for an optional
module, possibly repeated) only switches the collector back on. An import while the
collector is off for another reason (:mod:`seqrun.yamlsource` builds its trees that way)
leaves it off and freezes nothing.
"""

from __future__ import annotations

import gc
import importlib._bootstrap as _bootstrap
import threading

from seqrun import frozen_objects

_lock = threading.Lock()
_depth = 0
_collecting_before = False
_installed = False
_find_and_load = _bootstrap._find_and_load  # type: ignore[attr-defined]


def _find_and_load_without_collections(name, import_):
    """importlib's ``_find_and_load`` (a module not in sys.modules yet), the collector off
    meanwhile; the outermost one, on success, freezes what is alive."""
    global _depth, _collecting_before
    with _lock:
        _depth += 1
        if _depth == 1:
            _collecting_before = gc.isenabled()
            gc.disable()
    succeeded = False
    try:
        module = _find_and_load(name, import_)
        succeeded = True
        return module
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _collecting_before:
                if succeeded:
                    frozen_objects.keep()
                gc.enable()


def install() -> None:
    """Route importlib's module loading through the wrapper (once per process)."""
    global _installed
    if _installed:
        return
    _installed = True
    _bootstrap._find_and_load = _find_and_load_without_collections  # type: ignore[attr-defined]
