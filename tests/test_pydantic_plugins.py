"""The seqrun program validates without pydantic plugins unless the environment asks for them.

It sets pydantic's documented switch ``PYDANTIC_DISABLE_PLUGINS`` (as it sets
``OPENBLAS_NUM_THREADS``) unless the environment sets it. A fake installed package declares a
pydantic plugin that notes on stderr each validator it is given; the seqrun program runs
``validate --static`` with that package on the path.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from projecttree import ROOT

PROGRAM = """\
import atexit, os, sys
atexit.register(lambda: print("variable:", os.environ.get("PYDANTIC_DISABLE_PLUGINS"),
                              file=sys.stderr))
from seqrun.__main__ import main
main()
"""


def install_fake_plugin(folder: Path) -> None:
    (folder / "noting_plugin.py").write_text(textwrap.dedent("""\
        import sys

        class Plugin:
            def new_schema_validator(self, schema, schema_type, schema_type_path,
                                     schema_kind, config, plugin_settings):
                print("plugin saw", schema_type_path.name, file=sys.stderr)
                return None, None, None

        plugin = Plugin()
        """))
    info = folder / "noting_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: noting-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[pydantic]\nnoting = noting_plugin:plugin\n")


def run(folder: Path, **env: str) -> str:
    environment = {k: v for k, v in os.environ.items() if k != "PYDANTIC_DISABLE_PLUGINS"}
    environment.update(env, PYTHONPATH=f"{folder}{os.pathsep}{ROOT}")
    proc = subprocess.run([sys.executable, "-c", PROGRAM, "validate", "--static",
                           "sequences/opsafe.yaml"], cwd=ROOT, env=environment,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "opsafe.yaml: valid" in proc.stdout
    return proc.stderr


@pytest.fixture
def plugin_folder(tmp_path: Path) -> Path:
    install_fake_plugin(tmp_path)
    return tmp_path


def test_the_program_uses_no_plugin(plugin_folder):
    stderr = run(plugin_folder)
    assert "plugin saw" not in stderr
    assert "variable: __all__" in stderr


@pytest.mark.parametrize("value", ["", "another_plugin"])
def test_the_environment_can_ask_for_plugins(plugin_folder, value):
    stderr = run(plugin_folder, PYDANTIC_DISABLE_PLUGINS=value)
    assert "plugin saw Joint" in stderr and "plugin saw Sequence" in stderr
    assert f"variable: {value}\n" in stderr


def test_the_environment_can_disable_them_its_own_way(plugin_folder):
    stderr = run(plugin_folder, PYDANTIC_DISABLE_PLUGINS="true")
    assert "plugin saw" not in stderr and "variable: true" in stderr
