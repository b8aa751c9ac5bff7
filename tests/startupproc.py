"""Start-up mechanisms (seqrun.source_cache, pattern_cache, import_gc) tested in fresh
interpreters: each install() changes modules for the whole process, so each case gets its
own."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from projecttree import ROOT


def run_with_table(script: str, table: Path, mode: str, *, write: bool = True) -> dict:
    """Run ``script`` (it prints one JSON object) with arguments ``table`` and ``mode``; ``write=False`` as with
    ``PYTHONDONTWRITEBYTECODE`` (the table is read, never written)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    if not write:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    env["PYTHONPATH"] = str(ROOT)
    proc = subprocess.run([sys.executable, "-c", script, str(table), mode], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout)


def seqrun_program_at_exit(setup: str) -> list[str]:
    """Run ``seqrun pose list`` through the program's entry point after ``setup`` (code that
    registers an exit handler printing to stderr); the words on stderr."""
    code = f"{setup}\nfrom seqrun.entry import main\nmain()\n"
    proc = subprocess.run([sys.executable, "-c", code, "pose", "list"], cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stderr.split()
