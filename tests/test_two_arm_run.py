"""Two arms, one campaign (issue 28, items 1 and 4): ``seqrun run`` of a sequence for two
arms runs both together, each on its own (simulated) bus with its own run folder part;
one arm's fault halts both, or only itself when the campaign says so; a sequence whose
arms' paths cross is refused before anything opens."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from seqrun.cli import app
from twoarmskit import two_arm_campaign


@pytest.fixture
def campaign(tmp_path, monkeypatch):
    return two_arm_campaign(tmp_path, monkeypatch)


def run(*args: str):
    return CliRunner().invoke(app, ["run", *args, "--virtual-time", "--yes", "--no-report"])


def test_both_arms_run_together_each_in_its_part_of_the_run_folder(campaign, tmp_path):
    result = run("sequences/short.yaml", "--log-dir", str(tmp_path / "run"))
    assert result.exit_code == 0, result.output
    assert "arm A: PASSED" in result.output and "arm B: PASSED" in result.output
    summary = json.loads((tmp_path / "run" / "arms.json").read_text())
    assert summary["exit_code"] == 0 and set(summary["arms"]) == {"A", "B"}
    for arm in "AB":
        report = json.loads((tmp_path / "run" / arm / "report.json").read_text())
        assert report["status"] == "passed"
    a = [json.loads(l) for l in (tmp_path / "run" / "A" / "steps.jsonl").read_text().splitlines()]
    b = [json.loads(l) for l in (tmp_path / "run" / "B" / "steps.jsonl").read_text().splitlines()]
    a_turn = next(s for s in a if s.get("kind") == "move")
    b_turn = next(s for s in b if s.get("kind") == "move")
    # one time base: B's turn starts when A's has ended (it waited for A_turned); "t" is
    # when a step ended
    assert b_turn["t"] - b_turn["duration_s"] == pytest.approx(a_turn["t"], abs=0.03)


def test_a_fault_on_one_arm_halts_both_and_exits_3(campaign, tmp_path):
    result = run("sequences/short.yaml", "--log-dir", str(tmp_path / "run"),
                 "--sim-fault", "A/3:tow_error@0.2")
    assert result.exit_code == 3, result.output
    summary = json.loads((tmp_path / "run" / "arms.json").read_text())
    assert summary["first_fault"] == "A"
    assert summary["arms"]["B"]["halted_because_arm"] == "A"
    for arm in "AB":
        report = json.loads((tmp_path / "run" / arm / "report.json").read_text())
        assert report["fault"]["halt_sent"] and report["fault"]["halt_confirmed"], report
    assert "every arm was halted (on_fault = halt_all)" in result.output


@pytest.mark.parametrize("spec", ["B/4:tow_error@1.5", "B/all:halt@1.2", "B/2:drop_acks=1@1"])
def test_the_fault_campaign_on_one_arm_while_both_move(campaign, tmp_path, spec):
    result = run("sequences/short.yaml", "--log-dir", str(tmp_path / "run"), "--sim-fault",
                 spec)
    assert result.exit_code == 3, result.output
    summary = json.loads((tmp_path / "run" / "arms.json").read_text())
    assert summary["first_fault"] == "B"
    assert summary["arms"]["A"]["exit_code"] == 3
    report = json.loads((tmp_path / "run" / "A" / "report.json").read_text())
    assert report["fault"]["halt_sent"]


def test_crossing_paths_are_refused_before_anything_opens(campaign, tmp_path):
    result = run("sequences/paths_cross.yaml", "--log-dir", str(tmp_path / "run"))
    assert result.exit_code == 1
    assert "the arms' paths cross" in result.output
    assert "nothing was sent" in result.output
    assert not (tmp_path / "run").exists()


def test_one_arm_options_are_refused_with_several_arms(campaign):
    result = run("sequences/short.yaml", "--arm", "x.yaml")
    assert result.exit_code == 2
    assert "--arm: not for a campaign with several arms" in result.output
    result = run("sequences/short.yaml", "--sim-fault", "3:halt@1")
    assert result.exit_code == 2 and "ARM/SPEC" in result.output


def test_foxglove_with_several_arms_is_checked_before_anything_opens(campaign, tmp_path):
    """Issue 45: --foxglove serves a run of several arms (tests/test_foxglove_arms.py); a
    port it cannot listen on, or --foxglove-types alone, is one line, nothing opened."""
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        result = run("sequences/short.yaml", f"--foxglove={port}", "--log-dir",
                     str(tmp_path / "run"))
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: --foxglove: cannot listen on "
                                                   f"127.0.0.1:{port}"), result.output
    result = run("sequences/short.yaml", "--foxglove-types", "ros", "--log-dir",
                 str(tmp_path / "run"))
    assert result.exit_code == 2 and "only with --foxglove" in result.output, result.output
    assert not (tmp_path / "run").exists()   # nothing opened, nothing moved


def test_a_stop_request_goes_to_every_arm():
    """Ctrl-C and SIGTERM reach every arm's inbox (the signal handler posts once)."""
    from seqrun.cli.run_arms import EveryArm
    from seqrun.stop_requests import StopRequests

    inboxes = [StopRequests(), StopRequests()]
    every = EveryArm(inboxes)
    every.abort("Ctrl-C: controlled stop")
    every.halt("SIGTERM")
    for inbox in inboxes:
        kinds = [(r.kind, r.reason) for r in inbox.take()]
        assert kinds == [("abort", "Ctrl-C: controlled stop"), ("halt", "SIGTERM")]


# -- --zero-confirmed per arm (issue 45: it was refused for several arms) -----------------
@pytest.mark.slow  # three campaign runs
def test_zero_confirmed_for_every_arm_or_per_arm_runs(campaign, tmp_path):
    """A bare POSE is every arm's word, ID=POSE one arm's: each checked as for one arm (on
    the built-in simulator it must name the pose it was powered on at)."""
    for n, given in enumerate((["park"], ["A=park", "B=park"], ["totem", "A=park", "B=park"])):
        options = [w for pose in given for w in ("--zero-confirmed", pose)]
        result = run("sequences/short.yaml", *options, "--log-dir", str(tmp_path / f"r{n}"))
        assert result.exit_code == 0, (given, result.output)
        assert "arm A: PASSED" in result.output and "arm B: PASSED" in result.output


def test_zero_confirmed_of_another_pose_for_one_arm_is_refused_naming_it(campaign, tmp_path):
    result = run("sequences/short.yaml", "--zero-confirmed", "A=park", "--zero-confirmed",
                 "B=totem", "--log-dir", str(tmp_path / "run"))
    assert result.exit_code == 2, result.output
    assert result.output.strip().splitlines()[-1] == (
        "error: arm B: --zero-confirmed totem: the zero reference in force is Park (the "
        "simulator's power-on pose); nothing was sent")
    assert not (tmp_path / "run").exists()   # no run started


@pytest.mark.parametrize("given, line", [
    (["C=park"], "error: --zero-confirmed C=park: no arm 'C' here (arms A, B)"),
    (["A="], "error: --zero-confirmed A=: name the pose arm A stands in (e.g. A=park)"),
    (["A=park", "A=totem"], "error: --zero-confirmed: arm A named twice (A=park, A=totem)"),
    (["park", "totem"], "error: --zero-confirmed park and totem: one pose for every arm, "
                        "or ID=POSE for each arm"),
])
def test_a_bad_zero_confirmed_is_one_line_before_anything_opens(campaign, tmp_path, given,
                                                                line):
    options = [w for pose in given for w in ("--zero-confirmed", pose)]
    result = run("sequences/short.yaml", *options, "--log-dir", str(tmp_path / "run"))
    assert result.exit_code == 2
    assert result.output.strip() == line
    assert not (tmp_path / "run").exists()
