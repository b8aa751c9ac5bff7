"""A zero reference recorded for tests that drive `seqrun sim serve` as a real arm: the
served arm powers on at Park, and a real interface needs the record (issue: zero reference)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def with_park_recorded(env: dict, folder: Path) -> dict:
    """``env`` with its own state folder in ``folder`` holding a Park record."""
    env = {**env, "SEQRUN_STATE_DIR": str(folder / "zero-state")}
    done = subprocess.run([sys.executable, "-m", "seqrun", "zero", "set", "park", "--yes"],
                          capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    return env
