"""``seqrun fk`` and ``seqrun pose list/show`` through typer's CliRunner."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

import seqrun.cli.fk  # noqa: F401  (registers `fk`)
import seqrun.cli.pose  # noqa: F401  (registers `pose list/show`)
from projecttree import ROOT
from seqrun.cli.app import app
from seqrun.cli.fk import FkCommand

FILES = ["--arm", str(ROOT / "arms" / "lwa3.yaml"), "--poses-dir", str(ROOT / "poses")]
PARK = ["0", "-90", "0", "-120.32", "0", "115.74", "0"]

runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, list(args))


def assert_one_line_error(result, message: str, code: int = 2) -> None:
    assert result.exit_code == code, result.output
    assert result.stdout == ""
    assert result.stderr == f"error: {message}\n"
    assert isinstance(result.exception, SystemExit)  # not a crash, so no traceback


def test_negative_angles_as_typed():
    result = run("fk", "--deg", *PARK, "--json", *FILES)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == {
        "position_mm": [365.90268, -0.1, 47.920846],
        "rpy_deg": [0.0, 85.42, 180.0],
        "rotation": [[-0.079851, 0.0, -0.996807], [0.0, -1.0, 0.0], [-0.996807, 0.0, 0.079851]],
    }
    assert result.stderr == ""  # Park's j4 is j4's lower limit (arms/lwa3.yaml)


def test_an_angle_beyond_the_limits_is_a_note():
    beyond = list(PARK)
    beyond[3] = "-121"
    result = run("fk", "--deg", *beyond, "--json", *FILES)
    assert result.exit_code == 0, result.output
    assert result.stderr == "note: j4 -121 deg is outside its limits [-120.32, 120]\n"


def test_totem_json_is_the_reference_check_value():
    result = run("fk", "--json", *FILES, "--deg", "0", "0", "0", "0", "0", "0", "0")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == {
        "position_mm": [-0.006, -0.1, 1083.0],
        "rpy_deg": [180.0, 0.0, 0.0],
        "rotation": [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
    }
    assert result.stderr == ""


def test_human_readable_output():
    result = run("fk", "--deg", "70", "30", "0", "70", "20", "50", "0", *FILES)
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == [
        "position_mm   [-136.305, 510.761, 389.804]",
        "rpy_deg       [-22.318, -27.505, 124.351]",
        "rotation      [-0.500484, -0.862709, -0.072448]",
        "              [0.732280, -0.377203, -0.566995]",
        "              [0.461824, -0.336824, 0.820529]",
    ]


def test_pose_name_instead_of_angles():
    by_name = run("fk", "--pose", "park", "--json", *FILES)
    by_angles = run("fk", "--deg", *PARK, "--json", *FILES)
    assert by_name.exit_code == 0, by_name.output
    assert by_name.stdout == by_angles.stdout


def test_number_spellings():
    result = run("fk", "--deg", "-0", "-9e1", "0", "-.5", "+0", "1.5e+1", "-0.0", "--json", *FILES)
    assert result.exit_code == 0, result.output


def test_default_files_are_found_from_the_project_root(monkeypatch):
    monkeypatch.chdir(ROOT)
    assert run("fk", "--pose", "totem", "--json").exit_code == 0


@pytest.mark.parametrize(("args", "message"), [
    (["--deg", "0", "-90", "0"], "--deg needs 7 angles (j1 j2 j3 j4 j5 j6 j7), got 3"),
    (["--deg", *PARK, "5"], "--deg needs 7 angles (j1 j2 j3 j4 j5 j6 j7), got 8"),
    (["--deg", "0", "abc", "0", "0", "0", "0", "0"], "--deg: j2 'abc' is not a number"),
    (["--deg", "0", "0", "0", "0", "0", "0", "nan"], "--deg: j7 'nan' is not a finite angle"),
    (["--pose", "nowhere"],
     f"unknown pose 'nowhere'; available poses: opsafe, park, totem (in {ROOT / 'poses'})"),
    ([], "give the joint angles with --deg Q1 ... Qn or a pose with --pose NAME"),
    (["--deg", *PARK, "--pose", "park"], "give either --deg or --pose, not both"),
])
def test_user_mistakes_are_one_line_and_exit_2(args, message):
    assert_one_line_error(run("fk", *args, *FILES), message)


def test_missing_arm_file(tmp_path):
    missing = tmp_path / "arm.yaml"
    result = run("fk", "--deg", *PARK, "--arm", str(missing))
    assert_one_line_error(result, f"arm file {missing} not found (give one with --arm FILE)")


def test_unknown_option_after_the_angles_is_still_an_option():
    result = run("fk", "--deg", *PARK, "--jsn", *FILES)
    assert result.exit_code == 2
    assert "No such option: --jsn" in result.output


@pytest.mark.parametrize(("args", "spread"), [
    (["--deg", "0", "-90", "--json"], ["--deg", "0", "--deg", "-90", "--json"]),
    (["--json", "--deg", "-1e3", "x"], ["--json", "--deg", "-1e3", "--deg", "x"]),
    (["--deg", "--json"], ["--deg", "--json"]),
    (["--deg", "1", "--", "-2"], ["--deg", "1", "--", "-2"]),
    (["--arm", "a.yaml", "--deg", "-1", "-h"], ["--arm", "a.yaml", "--deg", "-1", "-h"]),
])
def test_values_after_deg_are_spread(args, spread):
    assert FkCommand.spread_values(args) == spread


# --- seqrun pose list / show -----------------------------------------------------------------

def test_pose_list():
    result = run("pose", "list", "--poses-dir", str(ROOT / "poses"))
    assert result.exit_code == 0, result.output
    assert [line.split()[:2] for line in result.stdout.splitlines()] == [
        ["opsafe", "reference"], ["park", "reference"], ["totem", "reference"]]


def test_pose_list_of_an_empty_directory(tmp_path):
    assert_one_line_error(run("pose", "list", "--poses-dir", str(tmp_path)),
                          f"no pose files in {tmp_path}")


def test_pose_show():
    result = run("pose", "show", "park", *FILES)
    assert result.exit_code == 0, result.output
    assert "joints_deg    j1 0, j2 -90, j3 0, j4 -120.32, j5 0, j6 115.74, j7 0" in result.stdout
    assert "position_mm   [365.903, -0.100, 47.921]" in result.stdout
    assert result.stderr == ""


def test_pose_show_reports_problems_with_exit_1(tmp_path):
    text = (ROOT / "poses" / "totem.yaml").read_text().replace("1083.0]", "1080.0]")
    (tmp_path / "totem.yaml").write_text(text)
    result = run("pose", "show", "totem", "--poses-dir", str(tmp_path),
                 "--arm", str(ROOT / "arms" / "lwa3.yaml"))
    assert result.exit_code == 1
    assert result.stderr == ("problem: end_effector.position_mm [-0.006, -0.100, 1080.000] is "
                             "3.000 mm from forward kinematics [-0.006, -0.100, 1083.000]\n")


def test_pose_show_unknown():
    result = run("pose", "show", "nowhere", *FILES)
    assert_one_line_error(
        result, f"unknown pose 'nowhere'; available poses: opsafe, park, totem (in {ROOT / 'poses'})")


def test_a_locked_joint_off_its_value_is_a_note_not_an_error():
    """fk is a maths command: it computes the configuration asked for and says that the arm
    would hold the locked joint elsewhere."""
    result = run("fk", "--deg", "0", "0", "5", "0", "0", "0", "0", "--json", *FILES)
    assert result.exit_code == 0, result.output
    assert result.stderr.strip() == ("note: j3 is locked at 0 deg on the arm; computed with "
                                     "5 deg as given")
    at_zero = json.loads(run("fk", "--deg", *["0"] * 7, "--json", *FILES).stdout)
    turned = json.loads(result.stdout)
    assert turned["rpy_deg"] != at_zero["rpy_deg"]  # j3's 5 deg is in the result
