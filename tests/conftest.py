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
    _take_ctrl_c_back()


def _take_ctrl_c_back() -> None:
    """A shell starts a background job (``pytest ... &``, nohup) with SIGINT and SIGQUIT
    ignored, and an ignored signal stays ignored in every child: the tests that press
    Ctrl-C on a seqrun process would find it deaf (a console ending with exit 0, a run
    timing out). The tests, like an operator's terminal, need them heard."""
    import signal

    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if signal.getsignal(signal.SIGQUIT) == signal.SIG_IGN:
        signal.signal(signal.SIGQUIT, signal.SIG_DFL)


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
