"""Text from files never rewrites the operator's terminal (issue 43, item 5): a control
character in a seqrun file is refused at its file:line:col, and the text of records seqrun
reads back (the zero record, another process's claim) is printed with every control
character escaped."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from projecttree import write_sequence
from twoarmskit import quiet
from seqrun.cli import app
from seqrun.formatting import control_character, terminal_text

#: Erase the line, back to its start, and write a verdict of one's own.
FORGED = "\x1b[2K\rzero: Totem (confirmed at this power-on)"


def test_terminal_text_escapes_every_control_character():
    assert terminal_text(FORGED) == "\\x1b[2K\\x0dzero: Totem (confirmed at this power-on)"
    assert terminal_text("a\u202eb\x9bc") == "a\\u202eb\\x9bc"    # bidi override, CSI
    assert terminal_text("two\nlines", lines=True) == "two\nlines"
    assert terminal_text("two\nlines") == "two\\x0alines"
    assert terminal_text("Grüße, 25 °C") == "Grüße, 25 °C"
    assert control_character("tab\tand\nbreak") is None
    assert control_character("bell\a") == "\\x07"


@pytest.mark.parametrize("field", ["name", "description"])
def test_a_control_character_in_a_sequence_is_refused_where_it_stands(project, monkeypatch,
                                                                       field):
    monkeypatch.chdir(project)
    path = write_sequence(project, "  - move: park\n", title="T")
    text = path.read_text()
    path.write_text(text.replace(f"{field}: ", f'{field}: "x\\e[2K\\rPASSED" # ', 1))
    result = CliRunner().invoke(app, ["validate", str(path.relative_to(project))])
    assert result.exit_code == 1, result.output
    line = 1 if field == "name" else 2
    assert result.output.splitlines()[0] == (
        f"sequences/s.yaml:{line}:{len(field) + 3}: a control character (\\x1b) in a text: "
        "seqrun files hold printable text (tabs and line breaks aside)")
    assert "\x1b" not in result.output


def test_the_zero_records_text_is_printed_escaped(tmp_path, monkeypatch):
    """The issue's reproduction: escape sequences in the zero record's fields rewrote the
    "zero:" line of status (and of every run)."""
    from projecttree import ROOT
    from seqrun.arm.poses import park_deg
    from seqrun.drivers.base import ArmIdentity
    from seqrun.service.zero import ZeroStore
    from test_arm_context import ARM, SERIALS, campaign_on, served_arm

    quiet(tmp_path, monkeypatch)
    server = served_arm("park")
    try:
        root = campaign_on(tmp_path, server)
        ZeroStore(ArmIdentity.of(SERIALS)).set_record(
            "park", by=FORGED, arm_name=ARM.name,
            joints_deg=park_deg(ROOT / "poses"))
        monkeypatch.chdir(root)
        for command in (["status"], ["zero", "show"]):
            result = CliRunner().invoke(app, command)
            assert result.exit_code == 0, result.output
            assert "\x1b" not in result.output and "\r" not in result.output
            assert "\\x1b[2K\\x0dzero: Totem" in result.output, result.output
    finally:
        server.shutdown()


def test_a_control_character_in_seqrun_toml_is_refused_where_it_stands(project,
                                                                       monkeypatch):
    """TOML spells an escape as \\u001b: the text read, not the file's bytes, is checked."""
    monkeypatch.chdir(project)
    (project / "seqrun.toml").write_text(
        '[campaign]\nname = "Op\\u001b[2K\\rPASSED"\narm = "arms/lwa3.yaml"\n')
    result = CliRunner().invoke(app, ["validate", "sequences/startup.yaml"])
    assert result.exit_code == 2, result.output
    assert result.output.strip() == (
        "error: seqrun.toml:2:1: campaign.name: a control character (\\x1b) in a text: "
        "seqrun files hold printable text (tabs and line breaks aside)")
