"""The dry run keeps what existed before it out of the collector's sight while it runs, and
gives it back after, unless the process keeps its objects frozen itself (the seqrun
program after its imports, the console): then it neither freezes nor unfreezes."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from projecttree import ROOT

SCRIPT = """
import gc, json, sys
from seqrun import frozen_objects
if sys.argv[1] == "kept":
    frozen_objects.keep()
calls = []
for name in ("freeze", "unfreeze"):
    def spy(real=getattr(gc, name), name=name):
        calls.append(name)
        return real()
    setattr(gc, name, spy)
before = gc.get_freeze_count()
from seqrun.cli import main
try:
    main(["validate", "sequences/opsafe.yaml"])
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "calls": calls, "before": before,
                  "after": gc.get_freeze_count()}))
"""


def dry_run_in_a_process(mode: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", SCRIPT, mode], cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_dry_run_freezes_for_its_duration_and_unfreezes_after():
    report = dry_run_in_a_process("plain")
    assert report["code"] in (0, None)
    assert report["calls"] == ["freeze", "unfreeze"]
    assert report["before"] == report["after"] == 0


def test_a_dry_run_leaves_a_process_that_keeps_its_objects_frozen_as_it_is():
    report = dry_run_in_a_process("kept")
    assert report["code"] in (0, None)
    assert "unfreeze" not in report["calls"] and "freeze" not in report["calls"]
    assert report["before"] > 0 and report["after"] > 0  # still frozen: nothing unfrozen
