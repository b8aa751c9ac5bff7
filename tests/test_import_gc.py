"""seqrun.import_gc: no cyclic collections during imports, what they made frozen after.

Each case runs in its own interpreter (install() changes importlib for the whole process),
importing small modules written to a temporary folder.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from projecttree import ROOT
from startupproc import seqrun_program_at_exit

SCRIPT = """\
import gc, json, sys
sys.path.insert(0, sys.argv[1])
if sys.argv[2] == "install":
    from seqrun import import_gc
    import_gc.install()
collections = []
gc.callbacks.append(lambda phase, info: phase == "start" and collections.append(1))
report = {}

def step(name, action):
    before, frozen = len(collections), gc.get_freeze_count()
    try:
        action()
        outcome = "ok"
    except Exception as exc:
        outcome = type(exc).__name__
    report[name] = {"outcome": outcome, "collections": len(collections) - before,
                    "frozen": gc.get_freeze_count() - frozen, "enabled": gc.isenabled()}

step("big", lambda: __import__("big"))            # imports "nested" too
step("again", lambda: __import__("big"))
step("missing", lambda: [__import__("no_such_module") for _ in range(3)])
step("broken", lambda: __import__("broken"))
gc.disable()
step("while_off", lambda: __import__("small"))
gc.enable()
step("after", lambda: __import__("late"))
step("cycles_are_collected_after", lambda: [[a := [], a.append(a)] for _ in range(5000)])
gc.collect()
report["garbage_frozen"] = (gc.unfreeze(), gc.collect())[1]
print(json.dumps(report))
"""

MODULES = {
    # ~200,000 objects, each in a cycle with the next: many collections without the wrapper
    "big.py": """\
        import nested
        NODES = []
        for i in range(200_000):
            NODES.append({"i": i, "all": NODES})
        """,
    "nested.py": "TABLE = [[i] for i in range(50_000)]\n",
    "broken.py": "DATA = [[i] for i in range(50_000)]\nraise RuntimeError('broken on purpose')\n",
    "small.py": "X = [[i] for i in range(20_000)]\n",
    "late.py": "Y = [[i] for i in range(20_000)]\n",
}


def run(tmp_path: Path, mode: str) -> dict:
    for name, text in MODULES.items():
        (tmp_path / name).write_text(textwrap.dedent(text))
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path), mode], cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout)


def test_an_import_runs_no_collection_and_freezes_what_it_made(tmp_path):
    plain, wrapped = run(tmp_path, "plain"), run(tmp_path, "install")
    assert plain["big"]["collections"] > 100 and plain["big"]["frozen"] == 0
    assert wrapped["big"] == {"outcome": "ok", "collections": 0,
                              "frozen": wrapped["big"]["frozen"], "enabled": True}
    assert wrapped["big"]["frozen"] > 250_000   # both modules' objects, frozen once
    assert wrapped["again"]["frozen"] == 0      # imported already: nothing happens


def test_failed_imports_freeze_nothing_and_leave_the_collector_on(tmp_path):
    wrapped = run(tmp_path, "install")
    for case in ("missing", "broken"):
        assert wrapped[case]["frozen"] == 0 and wrapped[case]["enabled"]
    assert wrapped["missing"]["outcome"] == "ModuleNotFoundError"
    assert wrapped["broken"]["outcome"] == "RuntimeError"


def test_an_import_while_the_collector_is_off_leaves_it_off(tmp_path):
    wrapped = run(tmp_path, "install")
    assert wrapped["while_off"] == {"outcome": "ok", "collections": 0, "frozen": 0,
                                    "enabled": False}
    assert wrapped["after"]["frozen"] > 0 and wrapped["after"]["enabled"]


def test_the_collector_still_frees_cycles_made_after_the_imports(tmp_path):
    wrapped = run(tmp_path, "install")
    assert wrapped["cycles_are_collected_after"]["collections"] > 0
    # what the freezes kept of garbage: little, and none of the cycles made after imports
    assert wrapped["garbage_frozen"] < 1_000


def test_the_seqrun_program_installs_it():
    words = seqrun_program_at_exit(
        "import atexit, sys, importlib._bootstrap as b, gc\n"
        "atexit.register(lambda: print(b._find_and_load.__module__, gc.isenabled(), "
        "gc.get_freeze_count() > 10_000, file=sys.stderr))")
    assert words[-3:] == ["seqrun.import_gc", "True", "True"]
