"""`-i ixxat` on Linux (python-can's ixxat interface needs IXXAT's Windows-only VCI driver)
says in one line how to reach the facility's adapter instead: as SocketCAN."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from seqrun.cli import app
from seqrun.service.adapters import adapter_hint


@pytest.mark.parametrize("command", [["status"], ["halt"], ["home"], ["limits", "show"]])
def test_ixxat_on_linux_is_one_line_naming_socketcan(command, tmp_path, monkeypatch):
    monkeypatch.setenv("SEQRUN_RUNTIME_DIR", str(tmp_path / "rt"))
    result = CliRunner().invoke(app, [*command, "-i", "ixxat", "-c", "0"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert lines[0].startswith("error: cannot open CAN interface 'ixxat' channel '0': ")
    assert "ip link set can0 type can bitrate 1000000 && sudo ip link set can0 up" in lines[0]
    assert "-i socketcan -c can0" in lines[0]
    assert "import" not in lines[0].lower() and "Traceback" not in result.output


def test_the_hint_is_for_ixxat_on_linux_only():
    assert adapter_hint("ixxat", "linux") is not None
    assert adapter_hint("ixxat", "win32") is None
    assert adapter_hint("socketcan", "linux") is None
