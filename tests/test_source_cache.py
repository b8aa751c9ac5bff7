"""seqrun.source_cache: the text dataclasses and typing compile, compiled once and kept.

Each case runs in its own interpreter (install() changes dataclasses and typing for the
whole process) with the table in a temporary folder.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from projecttree import ROOT
from startupproc import run_with_table, seqrun_program_at_exit

SCRIPT = """\
import json, sys
from pathlib import Path
from seqrun import source_cache
table = Path(sys.argv[1])
if sys.argv[2] == "install":
    source_cache.table_path = lambda: table
    source_cache.install()
import dataclasses, typing
import seqrun.events as events
from seqrun.powercube.codec import SetMotion
from seqrun.powercube.protocol import MotionMode
step = events.StepStarted(t=1.5, step=2, label="Up", kind="move", location="a.yaml:3:5")
motion = SetMotion(3, MotionMode.FRAMP_ACK, 0.25, None)
try:
    step.t = 2.0
    frozen = False
except dataclasses.FrozenInstanceError:
    frozen = True
init = events.StepStarted.__init__.__code__
hints = typing.get_type_hints(events.StepStarted)
import collections, inspect
Point = collections.namedtuple("Point", "x y", defaults=[0])
def annotated(a: "list[int]", b: "  dict[str, Point]") -> "Point | None": ...
annotations = inspect.get_annotations(annotated, eval_str=True)
source_cache.save()
print(json.dumps({
    "compiled": source_cache._compiled,
    "repr": repr(step) + repr(motion),
    "eq": step == events.StepStarted(t=1.5, step=2, label="Up", kind="move", location="a.yaml:3:5"),
    "hash": hash(motion) == hash(SetMotion(3, MotionMode.FRAMP_ACK, 0.25, None)),
    "frozen": frozen,
    "init": [init.co_code.hex(), repr(init.co_consts), init.co_names, init.co_varnames],
    "hints": {k: repr(v) for k, v in hints.items()},
    "namedtuple": [repr(Point(1)), Point.__new__.__code__.co_code.hex(),
                   Point.__new__.__code__.co_filename, Point.__new__.__defaults__],
    "annotations": {k: repr(v) for k, v in annotations.items()},
    "from_table": [key in source_cache._used for key in (
        ("eval", "list[int]"), ("eval", "dict[str, Point]"),
        ("eval", "lambda _cls, x, y: _tuple_new(_cls, (x, y))"))],
}))
"""


def run(table: Path, mode: str, *, write: bool = True) -> dict:
    return run_with_table(SCRIPT, table, mode, write=write)


def test_a_second_process_compiles_nothing_and_makes_the_same_classes(tmp_path):
    table = tmp_path / "generated-code.marshal"
    plain = run(table, "plain")
    first = run(table, "install")
    assert first["compiled"] > 100 and table.is_file()  # events' methods, forward refs
    second = run(table, "install")
    assert second["compiled"] == 0
    for result in (first, second):
        assert {k: v for k, v in result.items() if k not in ("compiled", "from_table")} == \
               {k: v for k, v in plain.items() if k not in ("compiled", "from_table")}
    assert plain["frozen"] and plain["eq"] and plain["hash"]
    assert plain["annotations"]["b"] == "dict[str, __main__.Point]"
    # the namedtuple's __new__ and the string annotations (eval skips leading blanks) too
    assert first["from_table"] == second["from_table"] == [True, True, True]


def test_no_table_is_written_when_bytecode_writing_is_off(tmp_path):
    table = tmp_path / "generated-code.marshal"
    assert run(table, "install", write=False)["compiled"] > 100
    assert not table.exists()


def test_a_damaged_table_is_ignored_and_replaced(tmp_path):
    table = tmp_path / "generated-code.marshal"
    table.write_bytes(b"\x00not a table")
    assert run(table, "install")["compiled"] > 100
    assert run(table, "install")["compiled"] == 0


def test_the_seqrun_program_installs_it():
    words = seqrun_program_at_exit(
        "import atexit, sys, dataclasses, typing\n"
        "atexit.register(lambda: print(dataclasses.exec.__module__, "
        "typing.compile.__module__, file=sys.stderr))")
    assert words[-2:] == ["seqrun.source_cache", "seqrun.source_cache"]


def test_entries_are_unmarshalled_only_when_used_and_a_damaged_one_is_compiled_again(tmp_path):
    import marshal

    from seqrun import source_cache

    table = tmp_path / "generated-code.marshal"
    run(table, "install")
    header, entries = marshal.loads(table.read_bytes())
    assert all(type(v) is bytes for v in entries.values())
    unused = ("eval", "list[int]  # text no process here compiles")
    entries[unused] = marshal.dumps(compile(unused[1], "<string>", "eval"))
    damaged = next(k for k in entries if k[0] == "exec")
    entries[damaged] = b"\x00damaged"
    table.write_bytes(marshal.dumps((header, entries)))
    probe = ("import json, sys\nfrom pathlib import Path\nfrom seqrun import source_cache\n"
             "source_cache.table_path = lambda: Path(sys.argv[1])\nsource_cache.install()\n"
             "import seqrun.events, seqrun.powercube.codec\n"
             "print(json.dumps({'compiled': source_cache._compiled, 'unused': "
             "type(source_cache._codes[tuple(sys.argv[2:])]).__name__}))\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONDONTWRITEBYTECODE": "1"}
    proc = subprocess.run([sys.executable, "-c", probe, str(table), *unused], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout)
    assert result == {"compiled": 1, "unused": "bytes"}  # the damaged entry, compiled again
    assert source_cache._FORMAT == header[0]
