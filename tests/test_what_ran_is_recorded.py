"""What ran is what is recorded (issue 23, item 4): the run folder keeps the bytes that
were validated, never the files read again, and ``run`` names every file used in place of
a shipped one (arm, pose) as ``validate`` does, in its output, report.json, record.json
and report.html."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
import seqrun.cli.run_start as run_start  # (where a terminal run asks its first question)
from seqrun.cli.app import app
from seqrun.sequence.loader import load_sequence
from seqrun.service import campaign_records
from seqrun.shipped import shipped_dir


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture
def campaign(tmp_path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    assert invoke("init", tmp_path / "camp").exit_code == 0
    return tmp_path / "camp"


def _only_run(campaign: Path) -> Path:
    (folder,) = (campaign / "runs").iterdir()
    return folder


def _copies(folder: Path) -> dict[str, dict]:
    record = json.loads((folder / "record.json").read_text())
    return {Path(entry["copy"]).name: entry for entry in record["inputs"]}


def test_a_pose_edited_while_the_run_waits_is_recorded_as_validated(campaign, monkeypatch):
    """The finding: a pose edited while the run waited at its first question; the run
    used the validated pose but inputs/ held the edited file."""
    shipped_totem = (shipped_dir("poses") / "totem.yaml").read_bytes()
    totem = campaign / "poses" / "totem.yaml"
    totem.write_bytes(shipped_totem)
    validated = totem.read_bytes()
    real_confirm_start = run_start._confirm_start

    def edit_while_asking(console, run, yes, *more):  # the operator takes their time
        totem.write_bytes(validated.replace(b"j2:", b"j2: 0  # edited\n  old_j2:", 1)
                          + b"# edited during the question\n")
        return real_confirm_start(console, run, yes, *more)

    monkeypatch.setattr(run_start, "_confirm_start", edit_while_asking)
    result = invoke("run", campaign / "sequences" / "first.yaml", "--yes", "--virtual-time",
                    "--plain", "--no-report")
    assert result.exit_code == 0, result.output
    assert totem.read_bytes() != validated  # the file did change
    folder = _only_run(campaign)
    entry = _copies(folder)["totem.yaml"]
    assert (folder / entry["copy"]).read_bytes() == validated
    assert entry["sha256"] == hashlib.sha256(validated).hexdigest()
    report = json.loads((folder / "report.json").read_text())
    by_name = {Path(i["file"]).name: i for i in report["inputs"]}
    assert by_name["totem.yaml"]["sha256"] == entry["sha256"]  # report and record agree


def test_every_input_copy_is_the_bytes_read_at_load(campaign):
    """Sequence, include, arm and seqrun.toml: all edited after loading, all recorded as
    loaded (the record is written from memory)."""
    first = campaign / "sequences" / "first.yaml"
    loaded = load_sequence(first)
    from seqrun.arm.description import load_arm

    arm = load_arm(loaded.arm_path)
    before = {p.name: p.read_bytes() for p in (first, campaign / "sequences" / "startup.yaml",
                                                 campaign / "seqrun.toml")}
    for name in ("first.yaml", "startup.yaml"):
        path = campaign / "sequences" / name
        path.write_text(path.read_text() + "# edited\n")
    (campaign / "seqrun.toml").write_text("[campaign]\nname = 'other'\n")
    folder = campaign / "runs" / "r"
    campaign_records.record_run(folder, loaded, loaded.arm_path, "SIMULATOR", None, arm=arm)
    copies = _copies(folder)
    for name, data in before.items():
        assert (folder / copies[name]["copy"]).read_bytes() == data, name
    assert (folder / copies["lwa3.yaml"]["copy"]).read_bytes() == arm.source_bytes


def _shadowing_arm(campaign: Path) -> Path:
    """The campaign's arms/lwa3.yaml with the desk guard removed."""
    text = (shipped_dir("arms") / "lwa3.yaml").read_text()
    guard = "    - {name: desk, min_z_mm: 10.0, points: [wrist, end_effector]}\n"
    assert guard in text
    path = campaign / "arms" / "lwa3.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(text.replace("  guards:\n" + guard, "  guards: []\n"))
    return path


def test_a_campaign_arm_shadowing_the_shipped_one_is_said_by_run_and_validate(campaign):
    arm = _shadowing_arm(campaign)
    (campaign / "poses" / "totem.yaml").write_bytes(
        (shipped_dir("poses") / "totem.yaml").read_bytes())
    first = campaign / "sequences" / "first.yaml"
    validated = invoke("validate", first, "--static")
    assert validated.exit_code == 0, validated.output
    result = invoke("run", first, "--yes", "--virtual-time", "--plain")
    assert result.exit_code == 0, result.output
    for output in (validated.output, result.output):
        assert f"arm file {arm.resolve()} is the campaign's, which shadows the shipped" \
            in output, output
        assert "pose 'totem' is the campaign's" in output, output
    # Said before anything moves, and kept with the run.
    lines = result.output.splitlines()
    note = next(i for i, line in enumerate(lines) if "shadows the shipped" in line)
    assert note < next(i for i, line in enumerate(lines) if line.startswith("[1/"))
    folder = _only_run(campaign)
    report = json.loads((folder / "report.json").read_text())
    record = json.loads((folder / "record.json").read_text())
    assert len(report["overrides"]) == 2 and record["overrides"] == report["overrides"]
    html = (folder / "report.html").read_text()
    assert "files in place of shipped ones" in html and "shadows the shipped" in html


def test_an_arm_outside_the_campaign_is_said(campaign, tmp_path):
    outside = tmp_path / "elsewhere" / "arms" / "my-arm.yaml"
    outside.parent.mkdir(parents=True)
    outside.write_bytes((shipped_dir("arms") / "lwa3.yaml").read_bytes())
    seq = campaign / "sequences" / "away.yaml"
    seq.write_text("name: Away\ndescription: x\narm: ../elsewhere/arms/my-arm.yaml\n"
                   "steps:\n  - include: startup.yaml\n")
    result = invoke("run", seq, "--yes", "--virtual-time", "--plain", "--no-report")
    assert result.exit_code == 0, result.output
    assert f"arm file {outside.resolve()} lies outside the campaign's folder" in result.output
    validated = invoke("validate", seq, "--static")
    assert f"arm file {outside.resolve()} lies outside" in validated.output


def test_the_shipped_files_get_no_note(campaign):
    result = invoke("run", campaign / "sequences" / "first.yaml", "--yes", "--virtual-time",
                    "--plain", "--no-report")
    assert result.exit_code == 0, result.output
    assert "shadows" not in result.output and "lies outside" not in result.output
    report = json.loads((_only_run(campaign) / "report.json").read_text())
    assert "overrides" not in report
