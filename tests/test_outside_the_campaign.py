"""Files from outside the campaign folder are named (issue 44, item 6): a pose file
symlinked from elsewhere, a whole poses/ symlinked, ``[runs] dir = ../outside/runs`` -
``validate`` and ``run`` say each in a note, as they already do for an arm file."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT
from seqrun.cli.app import app


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture
def camp(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    assert invoke("init", tmp_path / "camp").exit_code == 0
    (tmp_path / "outside").mkdir()
    monkeypatch.chdir(tmp_path / "camp")
    return tmp_path / "camp"


def notes(output: str) -> list[str]:
    return [line for line in output.splitlines() if "note:" in line]


def test_a_campaign_of_its_own_files_has_no_outside_note(camp):
    result = invoke("validate", "sequences/first.yaml", "--static")
    assert result.exit_code == 0, result.output
    assert not [n for n in notes(result.output) if "outside" in n and "limit" not in n]


def test_a_symlinked_pose_file_is_named_by_validate_and_run(camp):
    outside = camp.parent / "outside" / "totem.yaml"
    shutil.copy(ROOT / "poses" / "totem.yaml", outside)
    (camp / "poses" / "totem.yaml").symlink_to(outside)
    result = invoke("validate", "sequences/first.yaml", "--static")
    assert result.exit_code == 0, result.output
    [note] = [n for n in notes(result.output) if "is read from" in n]
    assert note.startswith("sequences/first.yaml:8:")   # the step naming the pose
    assert (f"pose 'totem' is read from {outside} (through the link "
            f"{camp / 'poses' / 'totem.yaml'}), outside the campaign's folder {camp}") in note
    run = invoke("run", "sequences/first.yaml", "--virtual-time", "--yes", "--plain",
                 "--no-report")
    assert run.exit_code == 0, run.output
    assert any(f"pose 'totem' is read from {outside}" in n for n in notes(run.output))


def test_a_symlinked_poses_folder_is_named(camp):
    folder = camp.parent / "outside" / "poses"
    folder.mkdir()
    shutil.copy(ROOT / "poses" / "totem.yaml", folder / "totem.yaml")
    shutil.rmtree(camp / "poses")
    (camp / "poses").symlink_to(folder, target_is_directory=True)
    result = invoke("validate", "sequences/first.yaml", "--static")
    assert result.exit_code == 0, result.output
    assert any(f"pose 'totem' is read from {folder / 'totem.yaml'}" in n
               and "outside the campaign's folder" in n for n in notes(result.output))


def test_a_runs_folder_outside_is_named_by_validate_and_run(camp):
    config = camp / "seqrun.toml"
    text = config.read_text()
    assert text.count('dir = "runs"') == 1
    config.write_text(text.replace('dir = "runs"', 'dir = "../outside/runs"'))
    line = next(n for n, raw in enumerate(config.read_text().splitlines(), start=1)
                if raw.startswith("dir ="))
    runs = (camp.parent / "outside" / "runs").resolve()
    expected = (f"seqrun.toml:{line}:1: note: [runs] dir = '../outside/runs': run folders "
                f"are written to {runs}, outside the campaign's folder {camp}")
    result = invoke("validate", "sequences/first.yaml", "--static")
    assert result.exit_code == 0, result.output
    assert expected in notes(result.output), result.output
    run = invoke("run", "sequences/first.yaml", "--virtual-time", "--yes", "--plain",
                 "--no-report")
    assert run.exit_code == 0, run.output
    assert any(f"run folders are written to {runs}" in n for n in notes(run.output))
    assert len(list(runs.iterdir())) == 1   # (and they are)


def test_a_two_arm_campaign_names_them_too(tmp_path, monkeypatch):
    """A campaign of several arms validates each arm's track: each names what it uses."""
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    camp = tmp_path / "two-arms"
    shutil.copytree(ROOT / "examples" / "two-arms", camp)
    (tmp_path / "outside").mkdir()
    shutil.copy(ROOT / "poses" / "totem.yaml", tmp_path / "outside" / "totem.yaml")
    (camp / "poses").mkdir()
    (camp / "poses" / "totem.yaml").symlink_to(tmp_path / "outside" / "totem.yaml")
    monkeypatch.chdir(camp)
    result = invoke("validate", "sequences/hold_and_approach.yaml", "--static")
    assert result.exit_code == 0, result.output
    found = [n for n in notes(result.output) if "is read from" in n]
    # at each arm's first step naming the pose (A's at line 18, B's at line 28)
    assert [n.split(": note")[0] for n in found] == [
        "sequences/hold_and_approach.yaml:18:26", "sequences/hold_and_approach.yaml:28:26"]
    assert all(f"pose 'totem' is read from {tmp_path / 'outside' / 'totem.yaml'}" in n
               for n in found)


@pytest.mark.slow  # a two-arm run
def test_a_two_arm_run_names_them_before_it_starts(tmp_path, monkeypatch):
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    camp = tmp_path / "two-arms"
    shutil.copytree(ROOT / "examples" / "two-arms", camp)
    (tmp_path / "outside").mkdir()
    with (camp / "seqrun.toml").open("a") as config:
        config.write('\n[runs]\ndir = "../outside/runs"\n')
    monkeypatch.chdir(camp)
    result = invoke("run", "sequences/hold_and_approach.yaml", "--sim", "--virtual-time",
                    "--yes", "--plain")
    assert result.exit_code == 0, result.output
    [note] = [n for n in notes(result.output) if "[runs] dir" in n]
    assert note.startswith("note: seqrun.toml:")
    assert f"run folders are written to {(tmp_path / 'outside' / 'runs').resolve()}" in note
    assert result.output.index(note) < result.output.index("A up to Totem")
