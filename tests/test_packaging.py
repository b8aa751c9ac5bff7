"""seqrun installed like any tool: the shipped arms, poses and sequences are package data.

The slow test installs the worktree non-editable into a fresh virtual environment and
uses it from an empty directory, with nothing of the checkout on the path.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from projecttree import ROOT


def test_every_seqrun_package_is_listed_for_the_wheel():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "seqrun").rglob(
        "__init__.py") if "__pycache__" not in p.parts}
    assert found <= listed, f"add to [tool.setuptools] packages: {sorted(found - listed)}"
    for kind in ("arms", "poses", "sequences"):
        assert config["package-dir"][f"seqrun._shipped.{kind}"] == kind
        assert config["package-data"][f"seqrun._shipped.{kind}"] == ["*.yaml"]


def test_the_checkout_finds_its_own_folders_as_the_shipped_ones():
    from seqrun.shipped import shipped_arm, shipped_dir

    assert shipped_dir("sequences") == ROOT / "sequences"
    assert shipped_arm("lwa3") == ROOT / "arms" / "lwa3.yaml"


@pytest.mark.slow
def test_a_non_editable_install_works_from_an_empty_directory(tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["SEQRUN_STATE_DIR"] = str(tmp_path / "state")
    install = subprocess.run([str(python), "-m", "pip", "install", "-q", str(ROOT)], env=env,
                             capture_output=True, text=True, timeout=900)
    assert install.returncode == 0, install.stderr[-3000:]
    empty = tmp_path / "empty"
    empty.mkdir()
    seqrun = str(venv / "bin" / "seqrun")

    def run(*args: str, cwd: Path = empty) -> subprocess.CompletedProcess:
        return subprocess.run([*args], cwd=cwd, env=env, capture_output=True, text=True,
                              timeout=300)

    where = run(str(python), "-c", "from seqrun.shipped import shipped_dir; "
                                   "print(shipped_dir('sequences'))")
    shipped = Path(where.stdout.strip())
    assert shipped.is_relative_to(venv), shipped  # the installed copy, not the checkout
    # PEP 561: the installed package says it is typed
    assert (shipped.parent.parent / "py.typed").is_file(), sorted(shipped.parent.parent.iterdir())
    valid = run(seqrun, "validate", str(shipped / "opsafe.yaml"))
    assert valid.returncode == 0, valid.stdout + valid.stderr
    assert "valid" in valid.stdout and "dry run from park" in valid.stdout
    assert run(seqrun, "init", "camp").returncode == 0
    campaign = run(seqrun, "validate", "camp")
    assert campaign.returncode == 0, campaign.stdout + campaign.stderr
    assert "2 files: all valid" in campaign.stdout
    ran = run(seqrun, "run", "camp/sequences/first.yaml", "--yes", "--virtual-time", "--plain")
    assert ran.returncode == 0, ran.stdout + ran.stderr
    listed = run(seqrun, "runs", cwd=empty / "camp")
    assert "First" in listed.stdout and "passed" in listed.stdout
