"""Short commands import only what they use; stdout closed early is a quiet end.

Which modules a command imports is asserted (``python -X importtime`` lists every import),
not how long it takes: timings belong to bench/bench_startup.py.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

from projecttree import ROOT, make_project
from runfolder import RunFolder

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def imported(*args: str) -> set[str]:
    """Top-level packages imported by ``python -m seqrun ARGS``."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "seqrun", *args],
                          cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    names = set()
    for line in proc.stderr.splitlines():
        if line.startswith("import time:") and "|" in line:
            name = line.rsplit("|", 1)[1].strip()
            names.add(name.split(".")[0])
    assert "seqrun" in names  # the listing really is the import log
    return names


def test_help_imports_no_heavy_package():
    assert not imported("--help") & {"can", "numpy", "ruckig", "pydantic", "rich", "yaml"}


@pytest.mark.slow  # four processes (the fast tier keeps --help's and validate's)
def test_sub_command_help_imports_no_bus_and_no_maths():
    for command in ("run", "validate", "status", "fk"):
        assert not imported(command, "--help") & {"can", "numpy", "ruckig"}, command


@pytest.mark.slow  # three processes (the fast tier keeps validate's)
def test_commands_without_a_bus_do_not_import_python_can():
    """python-can's import pulls in asyncio, ssl and sqlite3 (can.io); ssl alone may come
    from the standard library's xml.sax.saxutils (used by campaign validation)."""
    for args in (("fk", "--pose", "totem"), ("validate", "--static", "sequences/opsafe.yaml"),
                 ("pose", "list")):
        assert not imported(*args) & {"can", "asyncio", "sqlite3"}, args


def test_validate_and_its_dry_run_do_not_import_python_can():
    """The dry run talks to the simulator without python-can (seqrun.sim.port): its import
    (can.io: asyncio, ssl, sqlite3) cost more than a whole dry run of a short sequence."""
    assert not imported("validate", "sequences/opsafe.yaml") & {"can", "asyncio", "sqlite3"}


def imported_modules(*args: str, cwd: Path = ROOT) -> set[str]:
    """Every module ``python -m seqrun ARGS`` (run in ``cwd``) imports."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "seqrun", *args],
                          cwd=cwd, env=ENV, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return {line.rsplit("|", 1)[1].strip() for line in proc.stderr.splitlines()
            if line.startswith("import time:") and "|" in line}


def test_the_campaign_file_models_are_built_only_for_a_campaign(tmp_path):
    """The models of seqrun.toml are imported where one is read, not by every command."""
    outside = imported_modules("validate", "--static", "sequences/opsafe.yaml")
    assert "seqrun.sequence.project" in outside and "seqrun.sequence.campaign_config" not in outside
    campaign = make_project(tmp_path)
    inside = imported_modules("validate", "--static", "sequences/startup.yaml", cwd=campaign)
    assert "seqrun.sequence.campaign_config" in inside


def _head_one(args: list[str], cwd: Path = ROOT) -> tuple[int, str, str]:
    """Run ``seqrun ARGS | head -1``: read one line, close the pipe, wait for the end."""
    proc = subprocess.Popen([sys.executable, "-m", "seqrun", *args], cwd=cwd, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = proc.stdout.readline().decode()
    proc.stdout.close()
    _, err = proc.communicate(timeout=300)
    return proc.returncode, first, err.decode()


def test_a_closed_pipe_ends_a_command_quietly(tmp_path):
    """`seqrun validate … | head -1`: exit 141 like other tools, nothing on stderr (it was
    a silent exit 1, "invalid sequence")."""
    make_project(tmp_path, sequences=())
    steps = "".join("  - move: {joints: {j1: 500}}\n" for _ in range(1000))
    (tmp_path / "sequences" / "big.yaml").write_text(
        f"name: big\ndescription: two error lines per step\nsteps:\n{steps}")
    # ~190 kB of error lines: far beyond the pipe's buffer
    code, first, err = _head_one(["validate", "--static", "sequences/big.yaml"], tmp_path)
    assert first.startswith("sequences/big.yaml:4:5: ")
    assert code == 141, err
    assert err == ""


@pytest.mark.slow
def test_a_closed_pipe_never_ends_a_run(tmp_path):
    """A run goes on to its own end and exit code when its stdout goes away."""
    folder = tmp_path / "run"
    code, first, err = _head_one(["run", "--virtual-time", "--plain", "--log-dir", str(folder),
                                  "sequences/opsafe.yaml", "--yes"])
    assert first.strip()
    assert "Traceback" not in err
    report = RunFolder(folder).report()
    assert report["status"] == "passed", report.get("message")
    assert code == 0
    assert all(s["status"] == "passed" for s in report["steps"])


@pytest.mark.slow
def test_a_closed_pipe_during_a_fault_still_halts_and_exits_3(tmp_path):
    folder = tmp_path / "run"
    code, _, err = _head_one(["run", "--virtual-time", "--plain", "--log-dir", str(folder),
                              "--sim-fault", "4:tow_error@3", "sequences/opsafe.yaml", "--yes"])
    assert "Traceback" not in err
    report = RunFolder(folder).report()
    assert report["status"] == "failed" and report["fault"]["halt_sent"] is True
    assert code == 3


def test_piped_run_output_is_not_wrapped(tmp_path):
    """Into a pipe, a long line stays one line (rich wrapped at 80 columns mid-sentence)."""
    make_project(tmp_path, sequences=())
    label = "A label long enough to need more than eighty columns on a terminal " * 2
    (tmp_path / "sequences" / "long.yaml").write_text(
        f"name: long\ndescription: a long label\nsteps:\n  - reset: {{label: {label.strip()}}}\n")
    proc = subprocess.run([sys.executable, "-m", "seqrun", "run", "--virtual-time",
                           "--no-report", "--log-dir", str(tmp_path / "run"),
                           "sequences/long.yaml"],
                          cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert f"[1/1] {label.strip()} (" in proc.stdout
    assert any(len(line) > 120 for line in proc.stdout.splitlines())


def test_each_command_word_loads_the_module_that_defines_it():
    """`seqrun WORD …` imports only COMMAND_WORDS[WORD]: a wrong entry would make that
    command unknown to the program (while every test, importing all modules, passed)."""
    import seqrun.cli
    from seqrun.cli.app import app

    defined = {c.name: c.callback.__module__ for c in app.registered_commands}
    for group in app.registered_groups:
        modules = {c.callback.__module__ for c in group.typer_instance.registered_commands}
        assert len(modules) == 1, (group.name, modules)
        defined[group.name] = modules.pop()
    assert seqrun.cli.COMMAND_WORDS == defined


MODULES_AT_EXIT = """\
import atexit, sys
atexit.register(lambda: print(sorted(sys.modules), file=sys.stderr))
from seqrun.__main__ import main
main()
"""


def test_a_command_runs_with_only_its_own_module_loaded():
    proc = subprocess.run([sys.executable, "-c", MODULES_AT_EXIT, "pose", "list"],
                          cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "totem" in proc.stdout
    loaded = set(ast.literal_eval(proc.stderr.strip().splitlines()[-1]))
    assert "seqrun.cli.pose" in loaded
    assert not loaded & {"seqrun.cli.run", "seqrun.cli.validate", "seqrun.cli.sim"}


THREADS_AT_EXIT = """\
import atexit, os
atexit.register(lambda: print(len(os.listdir("/proc/self/task")), file=os.sys.stderr))
from seqrun.__main__ import main
main()
"""


def test_a_command_starts_no_blas_thread_pool():
    """OpenBLAS starts one thread per core when numpy is imported (about half of numpy's
    import time); seqrun's 4x4 and 6x7 matrices gain nothing from them."""
    env = {k: v for k, v in ENV.items() if k != "OPENBLAS_NUM_THREADS"}
    proc = subprocess.run([sys.executable, "-c", THREADS_AT_EXIT, "fk", "--pose", "totem"],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "position_mm" in proc.stdout
    assert proc.stderr.strip().splitlines()[-1] == "1"  # the main thread only


def test_a_dry_run_does_not_load_the_arm_session():
    """seqrun.service.runner needs seqrun.service.run_control; the package used to import the whole
    arm session (seqrun.service.session) with it."""
    proc = subprocess.run([sys.executable, "-c", MODULES_AT_EXIT, "validate",
                           "sequences/opsafe.yaml"],
                          cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "dry run from park" in proc.stdout
    loaded = set(ast.literal_eval(proc.stderr.strip().splitlines()[-1]))
    assert "seqrun.service.run_control" in loaded
    assert "seqrun.service.session" not in loaded
