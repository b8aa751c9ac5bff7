"""Which tier this pytest run is: the fast loop (``pytest -m "not slow"``) or everything
(CI's ``pytest -n 2``). Property tests draw fewer examples in the fast loop; CI draws the
full count (``SEQRUN_EXAMPLES=full`` gives the full count in the fast loop too)."""

from __future__ import annotations

import os

from hypothesis import settings

#: Set by conftest.py's ``pytest_configure`` (before any test module is imported).
FAST = False
#: The fast loop's share of each property test's examples.
FAST_SHARE = 4

# The fast loop's profile: the default count (100) for tests that set none, shared alike.
settings.register_profile("fast", max_examples=100 // FAST_SHARE)


def configure(markexpr: str) -> None:
    """Choose the tier from the ``-m`` expression of the run."""
    global FAST
    FAST = (" ".join(markexpr.split()) == "not slow"
            and os.environ.get("SEQRUN_EXAMPLES") != "full")
    if FAST:
        settings.load_profile("fast")


def examples(full: int) -> int:
    """``max_examples`` for a property test: ``full`` (CI), or a quarter of it, at least
    10, in the fast loop."""
    return max(10, full // FAST_SHARE) if FAST else full
