"""Campaign folders: seqrun init, lookups (poses, arm, includes), config errors, and the
campaign-wide validation (summary table, --json, --junit, exit codes)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT
from seqrun.cli.app import app
from seqrun.errors import SequenceInvalid
from seqrun.sequence.project import ConfigInvalid, load_config, project_for
from seqrun.sequence.loader import load_sequence
from seqrun.shipped import shipped_dir


def invoke(*args: str, **kwargs):
    return CliRunner().invoke(app, [str(a) for a in args], **kwargs)


@pytest.fixture
def campaign(tmp_path, monkeypatch) -> Path:
    """A fresh campaign, with the current directory elsewhere (as an installed tool)."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    result = invoke("init", tmp_path / "camp")
    assert result.exit_code == 0, result.output
    return tmp_path / "camp"


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def test_init_creates_config_sequences_and_poses(campaign):
    assert (campaign / "seqrun.toml").is_file()
    assert (campaign / "sequences" / "first.yaml").is_file()
    assert (campaign / "sequences" / "startup.yaml").is_file()
    assert (campaign / "poses").is_dir()
    config = load_config(campaign / "seqrun.toml")
    assert config.campaign.name == "camp" and config.campaign.arm == "lwa3"
    assert config.runs.dir == "runs" and config.bus.interface is None


def test_init_refuses_an_existing_campaign(campaign):
    result = invoke("init", campaign)
    assert result.exit_code == 2
    assert "is a campaign already" in result.output


def test_a_fresh_campaign_validates_from_anywhere(campaign):
    result = invoke("validate", campaign)
    assert result.exit_code == 0, result.output
    assert "sequences/first.yaml" in result.output and "2 files: all valid" in result.output


def test_shipped_poses_and_arm_are_found_without_a_project_folder(campaign):
    loaded = load_sequence(campaign / "sequences" / "first.yaml")
    assert loaded.project.root == campaign.resolve()
    assert loaded.pose_path == (campaign.resolve() / "poses", shipped_dir("poses"))
    assert loaded.arm_path == (shipped_dir("arms") / "lwa3.yaml").resolve()


def test_campaign_poses_add_to_and_override_the_shipped_ones(campaign):
    opsafe = (ROOT / "poses" / "opsafe.yaml").read_text()
    write(campaign / "poses" / "low.yaml", opsafe.replace("name: opsafe", "name: low"))
    totem = (ROOT / "poses" / "totem.yaml").read_text()
    write(campaign / "poses" / "totem.yaml", totem.replace("Totem: arm vertical",
                                                           "Totem (campaign copy)"))
    write(campaign / "sequences" / "two.yaml",
          "name: Two\ndescription: own pose and overridden pose\nsteps:\n"
          "  - include: startup.yaml\n  - move: totem\n  - move: low\n")
    result = invoke("validate", campaign / "sequences" / "two.yaml", "--static")
    assert result.exit_code == 0, result.output
    assert (f"two.yaml:5:11: note: pose 'totem' is the campaign's "
            f"{campaign.resolve() / 'poses' / 'totem.yaml'}, which overrides "
            f"{shipped_dir('poses') / 'totem.yaml'}") in result.output.replace("\n", "")


def test_an_unknown_pose_names_every_place_searched(campaign):
    write(campaign / "sequences" / "lost.yaml",
          "name: Lost\ndescription: x\nsteps:\n  - include: startup.yaml\n  - move: nowhere\n")
    with pytest.raises(SequenceInvalid) as info:
        load_sequence(campaign / "sequences" / "lost.yaml")
    message = str(info.value.errors[0])
    assert f"searched {campaign.resolve() / 'poses'}, {shipped_dir('poses')}" in message
    assert "available poses: opsafe, park, totem" in message


def test_includes_may_reach_anywhere_inside_the_campaign_but_not_out(campaign, tmp_path):
    write(campaign / "common" / "up.yaml", "name: Up\ndescription: x\nsteps:\n  - move: totem\n")
    write(campaign / "sequences" / "deep" / "inc.yaml",
          "name: Inc\ndescription: x\nsteps:\n  - include: ../startup.yaml\n"
          "  - include: ../../common/up.yaml\n")
    loaded = load_sequence(campaign / "sequences" / "deep" / "inc.yaml")
    assert [s.kind for s in loaded.steps] == ["reset", "home", "set_limits", "move"]
    write(tmp_path / "outside.yaml", "name: O\ndescription: x\nsteps:\n  - wait: 1\n")
    write(campaign / "sequences" / "escape.yaml",
          "name: E\ndescription: x\nsteps:\n  - include: ../../outside.yaml\n")
    with pytest.raises(SequenceInvalid, match="outside the campaign folder"):
        load_sequence(campaign / "sequences" / "escape.yaml")


def test_a_missing_arm_names_the_places_searched(campaign):
    config = campaign / "seqrun.toml"
    config.write_text(config.read_text().replace('arm = "lwa3"', 'arm = "lwa9"'))
    result = invoke("validate", campaign / "sequences" / "first.yaml")
    assert result.exit_code == 2
    assert result.output.strip() == (
        f"error: arm 'lwa9' not found (looked for {campaign.resolve() / 'arms' / 'lwa9.yaml'}, "
        f"{shipped_dir('arms') / 'lwa9.yaml'})")


def test_project_option_names_the_campaign(campaign, tmp_path):
    write(campaign / "poses" / "mine.yaml",
          (ROOT / "poses" / "opsafe.yaml").read_text().replace("name: opsafe", "name: mine"))
    loose = write(tmp_path / "loose" / "seq.yaml",
                  "name: L\ndescription: x\nsteps:\n  - include: ../camp/sequences/startup.yaml\n"
                  "  - move: totem\n  - move: mine\n")
    assert project_for(loose).root != campaign.resolve()
    without = invoke("validate", loose, "--static")
    assert without.exit_code == 1 and "unknown pose 'mine'" in without.output
    assert invoke("validate", loose, "--static", "--project", campaign).exit_code == 0


def test_an_unknown_project_folder_is_one_line(tmp_path):
    result = invoke("validate", ROOT / "sequences" / "totem.yaml", "--project",
                    tmp_path / "nope")
    assert result.exit_code == 2
    assert result.output.strip() == f"error: project folder {tmp_path / 'nope'} does not exist"


@pytest.mark.parametrize("text, where, message", [
    ('[campaign]\nname = "x\n', "2:10", "invalid TOML: Illegal character"),
    ('[campaign]\nname = "x"\n\n[bus]\nbitrate = 99\n', "5:1", "bus.bitrate: "),
    ('[runs]\nfolder = "r"\n', "2:1", "runs.folder: unknown key (expected: dir)"),
    ('[campain]\n', "1:1", "campain: unknown key (expected: campaign, bus, runs, ros, sim, arms)"),
    # Hostile files (issue 23, item 6): one line at the toml's own line, never a traceback.
    ('[campaign]\nname = "x\0y"\n', "2:10", "invalid TOML: Illegal character"),
    ('[bus]\nbitrate = 500000.0\n', "2:1", "bus.bitrate: a bit rate is a whole number"),
    ('[bus]\nbitrate = true\n', "2:1", "bus.bitrate: a bit rate is a whole number"),
    ("\n\nbomb = " + "[" * 100_000 + "]" * 100_000 + "\n", "3:40",
     "invalid TOML: arrays or tables nested more than 32 deep"),
    ('[bus]\nkwargs = {a = ' + "{b = " * 3000 + "1" + "}" * 3000 + "}\n", "2:170",
     "invalid TOML: arrays or tables nested more than 32 deep"),
    ('[campaign]\nname = "' + "[" * 50 + '"\n', None, None),  # brackets in a string: fine
    ('[campaign]\nname = """\n' + "{" * 50 + '\n"""\n', None, None),
])
def test_a_broken_config_is_file_line_col_and_exit_2(campaign, text, where, message):
    if where is None:  # not broken: the scan for nesting skips strings
        (campaign / "seqrun.toml").write_text(text)
        load_config(campaign / "seqrun.toml")
        return
    (campaign / "seqrun.toml").write_text(text)
    with pytest.raises(ConfigInvalid) as info:
        load_config(campaign / "seqrun.toml")
    assert f"seqrun.toml:{where}: {message}" in str(info.value)
    result = invoke("validate", campaign / "sequences" / "first.yaml")
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and f":{where}: " in lines[0]
    assert "Traceback" not in result.output


def test_campaign_validation_table_json_junit_and_exit_code(campaign, tmp_path):
    write(campaign / "sequences" / "bad.yaml",
          "name: Bad\ndescription: x\nsteps:\n  - include: startup.yaml\n"
          "  - move: {joints: {j2: 150}}\n")
    junit = tmp_path / "out" / "junit.xml"
    result = invoke("validate", campaign, "--junit", junit)
    assert result.exit_code == 1
    assert "bad.yaml:5:25: j2 target 150° is outside its limits -120…120" in result.output
    header = next(line for line in result.output.splitlines() if line.startswith("file"))
    assert header.split() == ["file", "result", "simulated", "lowest", "guard", "clearance",
                              "findings"]
    assert "3 files: 1 not valid" in result.output
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite.get("tests") == "3" and suite.get("failures") == "1"
    as_json = json.loads(invoke("validate", campaign, "--json").output)
    assert as_json["valid"] is False
    first = next(r for r in as_json["results"] if r["file"].endswith("first.yaml"))
    assert first["result"] == "valid" and first["simulated_s"] > 8
    assert 30 < first["lowest_guard_clearance_mm"] < 45  # end-effector above the desk guard
    (campaign / "sequences" / "bad.yaml").unlink()
    assert invoke("validate", campaign, "--json").exit_code == 0


def test_static_checks_of_changed_files_as_the_pre_commit_hook_runs_them(campaign):
    pose = write(campaign / "poses" / "bent.yaml",
                 (ROOT / "poses" / "park.yaml").read_text().replace("j1: 0.0", "j1: 10.0"))
    result = invoke("validate", "--static", campaign / "sequences" / "first.yaml", pose)
    assert result.exit_code == 1
    assert "from forward kinematics" in result.output
    assert "name 'park' differs from the file name 'bent'" in result.output
    hooks = (ROOT / ".pre-commit-hooks.yaml").read_text()
    assert "entry: seqrun validate --static" in hooks


def test_the_shipped_sequences_validate_as_a_campaign_from_the_repository(monkeypatch):
    monkeypatch.chdir(ROOT)
    result = invoke("validate", "sequences", "--static")
    assert result.exit_code == 0, result.output
    shipped = len(list((ROOT / "sequences").glob("*.yaml")))
    assert shipped >= 6  # startup, totem, opsafe, park, shutdown, linear_approach, ...
    assert f"{shipped} files: all valid" in result.output


def test_legacy_layout_still_finds_project_poses_first(tmp_path, monkeypatch):
    """A folder with poses/ but no seqrun.toml: its poses first, then the shipped ones."""
    write(tmp_path / "proj" / "poses" / "mine.yaml",
          (ROOT / "poses" / "totem.yaml").read_text().replace("name: totem", "name: mine"))
    seq = write(tmp_path / "proj" / "sequences" / "s.yaml",
                "name: S\ndescription: x\nsteps:\n  - reset\n  - home\n  - set_limits\n"
                "  - move: mine\n  - move: opsafe\n")
    loaded = load_sequence(seq)
    assert loaded.pose_path[0] == (tmp_path / "proj" / "poses").resolve()
    assert loaded.arm_path == (shipped_dir("arms") / "lwa3.yaml").resolve()


def test_pose_fk_and_status_work_from_an_empty_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    listed = invoke("pose", "list")
    assert listed.exit_code == 0 and "opsafe" in listed.output and "totem" in listed.output
    assert invoke("fk", "--pose", "opsafe", "--json").exit_code == 0
    status = invoke("status", "--sim", "--json")
    assert status.exit_code == 0, status.output
    assert json.loads(status.output)["joints"][1]["position_deg"] == -90.0  # at Park


def test_a_campaigns_own_poses_are_listed_inside_it(campaign, monkeypatch):
    write(campaign / "poses" / "mine.yaml",
          (ROOT / "poses" / "opsafe.yaml").read_text().replace("name: opsafe", "name: mine"))
    monkeypatch.chdir(campaign)
    names = [line.split()[0] for line in invoke("pose", "list").output.splitlines()]
    assert names == ["mine", "opsafe", "park", "totem"]


def test_run_uses_the_campaigns_bus_settings(campaign):
    config = campaign / "seqrun.toml"
    config.write_text(config.read_text().replace(
        '# interface = "ixxat"', 'interface = "socketcand"\nkwargs = {host = "127.0.0.1", '
                                 'port = 9}'))
    result = invoke("run", campaign / "sequences" / "first.yaml", "--yes", "--plain")
    assert result.exit_code == 2
    assert "no socketcand server at 127.0.0.1:9" in result.output
    assert invoke("run", campaign / "sequences" / "first.yaml", "--yes", "--plain", "--sim",
                  "--virtual-time", "--no-report").exit_code == 0  # --sim: the simulator all the same


def test_a_sequence_may_name_its_arm_by_name_or_by_file(campaign):
    seq = write(campaign / "sequences" / "named.yaml",
                "name: N\ndescription: x\narm: lwa3\nsteps:\n  - wait: 1\n")
    assert load_sequence(seq).arm_path == (shipped_dir("arms") / "lwa3.yaml").resolve()
    own = write(campaign / "arms" / "lwa3.yaml", (ROOT / "arms" / "lwa3.yaml").read_text())
    assert load_sequence(seq).arm_path == own.resolve()  # the campaign's comes first
    seq.write_text(seq.read_text().replace("arm: lwa3", "arm: arms/other.yaml"))
    with pytest.raises(SequenceInvalid) as info:
        load_sequence(seq)
    assert f"arm file 'arms/other.yaml' not found (looked for " \
           f"{campaign.resolve() / 'arms' / 'other.yaml'})" in str(info.value.errors[0])


def test_every_schema_a_campaign_file_names_exists(campaign):
    """Issue 23 (item 8): startup.yaml named ../docs/schema/sequence.schema.json, which a
    campaign did not have. seqrun init writes the schemas the files name (those of
    docs/schema/), and the starter names its schema too."""
    named = {}
    for path in campaign.rglob("*.yaml"):
        first = path.read_text(encoding="utf-8").splitlines()[0]
        assert first.startswith("# yaml-language-server: $schema="), path
        named[path] = path.parent / first.split("$schema=", 1)[1]
    assert {p.name for p in named} == {"first.yaml", "startup.yaml"}
    for path, schema in named.items():
        assert schema.is_file(), f"{path} names {schema}, which does not exist"
        assert schema.read_text() == (ROOT / "docs" / "schema" / schema.name).read_text()
    pose_schema = campaign / "poses" / "../docs/schema/pose.schema.json"  # pose save's comment
    assert pose_schema.is_file()
    assert invoke("validate", campaign).exit_code == 0


@pytest.mark.parametrize("command", [["status"], ["halt"], ["reset"], ["fk"], ["ik"],
                                     ["console"], ["pose", "save"], ["zero", "show"]])
def test_the_arm_option_says_what_it_really_uses(command):
    """Issue 23 (item 8): the help said "[default: arms/lwa3.yaml]" while the command used
    the campaign's arm (or the shipped one) when there is no such file."""
    help_text = " ".join(invoke(*command, "--help").output.split())
    assert "[default: arms/lwa3.yaml]" not in help_text
    assert "the arm of the campaign here (its seqrun.toml), else the shipped lwa3" in help_text


def test_status_uses_the_arm_its_help_names(campaign, monkeypatch):
    mine = (shipped_dir("arms") / "lwa3.yaml").read_text().replace(
        "name: ", "name: Mine, not ", 1)
    write(campaign / "arms" / "mine.yaml", mine)
    config = campaign / "seqrun.toml"
    config.write_text(config.read_text().replace('arm = "lwa3"', 'arm = "arms/mine.yaml"'))
    monkeypatch.chdir(campaign)
    result = invoke("status", "--sim")
    assert result.exit_code == 0, result.output
    assert "Mine, not " in result.output
