"""seqrun/ type-checks clean with the project's mypy settings (pyproject.toml): the README's
test command, which CI runs, runs mypy through this test."""

from __future__ import annotations

import subprocess
import sys

import pytest

from projecttree import ROOT


@pytest.mark.slow
def test_seqrun_type_checks():
    done = subprocess.run([sys.executable, "-m", "mypy", "--config-file",
                           str(ROOT / "pyproject.toml")],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Success: no issues found" in done.stdout
