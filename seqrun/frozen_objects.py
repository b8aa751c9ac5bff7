"""Whether this process keeps its long-lived objects out of the cyclic collector's view.

Two places call :func:`gc.freeze`: the console once it serves
(:func:`seqrun.service.realtime.keep_long_lived_objects_out_of_collections`), and a dry run
for its own duration when nobody else did (:mod:`seqrun.service.dryrun`, which unfreezes after).
The dry run must know whether the others did, and :func:`gc.get_freeze_count` walks the
whole frozen list to answer (every object a process has imported): so the freezes that
stay say so here.
"""

from __future__ import annotations

import gc

_kept = False


def keep() -> None:
    """Freeze every object alive now, for the rest of the process."""
    global _kept
    gc.freeze()
    _kept = True


def kept() -> bool:
    """Whether :func:`keep` was called in this process."""
    return _kept
