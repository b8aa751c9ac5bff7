"""Fixtures every test file may use. The helper modules beside this file (projecttree,
runfolder, fakebus, wrapbus, …) are imported by name: pytest puts this folder on sys.path.

Tiers: ``pytest -m "not slow"`` is the fast loop; ``pytest -n 2`` (CI) runs everything.
Property tests draw a quarter of their examples in the fast loop (tiers.py)."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest

import tiers
from projecttree import make_project, shipped_arm
from seqrun.arm.description import ArmDescription


def pytest_configure(config: pytest.Config) -> None:
    tiers.configure(config.getoption("markexpr") or "")


@pytest.fixture(scope="session")
def arm() -> ArmDescription:
    """The shipped arm (arms/lwa3.yaml), loaded once."""
    return shipped_arm()


@pytest.fixture
def project(tmp_path: Path) -> Path:
    """A campaign of the test's own: seqrun.toml, arms/, poses/, sequences/startup.yaml."""
    return make_project(tmp_path / "project")


@pytest.fixture(autouse=True)
def private_runtime_dir(monkeypatch):
    """Every test its own runtime directory (bus claims, control sockets): a run or console
    of one test (or of another checkout's tests on this machine) is never "live" for
    another test's ``seqrun halt``. Short, under /tmp: a unix socket path has ~100 bytes."""
    folder = tempfile.mkdtemp(prefix="sqrt-")
    monkeypatch.setenv("SEQRUN_RUNTIME_DIR", folder)
    yield Path(folder)
    shutil.rmtree(folder, ignore_errors=True)
