"""What a two-arm run leaves behind (issue 28, item 3): both arms on ONE time base
(``arms.json`` gives each arm's start on the run clock and the wall clock; events and CAN
traces of both arms lie on one time line), and one ``<run>/run.mcap`` with both arms'
topics namespaced by arm id, stamped on that time base, in log-time order."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from armsrecordkit import (check_b_moves_after_a_signalled, check_one_time_base,
                           check_run_mcap, check_traces_on_the_one_time_base, read_mcap)
from typer.testing import CliRunner

from seqrun.cli import app
from twoarmskit import two_arm_campaign


_campaign = two_arm_campaign


def _run(folder: Path, *extra: str) -> Path:
    result = CliRunner().invoke(app, ["run", "sequences/short.yaml", "--sim", "--yes",
                                      "--no-report", "--log-dir", str(folder), *extra])
    assert result.exit_code == 0, result.output
    return folder


@pytest.fixture(scope="module")
def virtual_run(tmp_path_factory):
    """One run of both arms at virtual time (shared by the tests that only read it)."""
    base = tmp_path_factory.mktemp("two-arm-records")
    with pytest.MonkeyPatch.context() as mp:
        _campaign(base, mp)
        yield _run(base / "run", "--virtual-time")


def test_both_arms_start_on_one_time_base_at_virtual_time(virtual_run):
    check_one_time_base(virtual_run)
    summary = json.loads((virtual_run / "arms.json").read_text())
    assert summary["time_base"]["clock"] == "virtual"
    assert summary["time_base"]["epoch_s"] == int(summary["time_base"]["epoch_s"])


def test_b_waits_for_as_signal_on_the_common_time_line(virtual_run):
    check_b_moves_after_a_signalled(virtual_run)


def test_both_traces_are_on_the_one_time_base(virtual_run):
    check_traces_on_the_one_time_base(virtual_run,
                                      check_b_moves_after_a_signalled(virtual_run))


@pytest.mark.slow
def test_one_time_base_in_real_time(tmp_path, monkeypatch):
    run = _run(_campaign(tmp_path, monkeypatch) / "runs" / "real")
    summary = json.loads((run / "arms.json").read_text())
    assert summary["time_base"]["clock"] == "monotonic"
    check_one_time_base(run)
    check_traces_on_the_one_time_base(run, check_b_moves_after_a_signalled(run))
    check_run_mcap(run)


# -- <run>/run.mcap -----------------------------------------------------------------------
def test_run_mcap_holds_both_arms_on_the_common_clock(virtual_run):
    check_run_mcap(virtual_run)


def test_report_mcap_writes_the_same_run_mcap_again(virtual_run, tmp_path):
    live = read_mcap(virtual_run / "run.mcap")
    copy = tmp_path / "run"
    shutil.copytree(virtual_run, copy)
    (copy / "run.mcap").unlink()
    result = CliRunner().invoke(app, ["report", str(copy), "--mcap"])
    assert result.exit_code == 0, result.output
    assert result.output.startswith(f"wrote {copy / 'run.mcap'} ({len(live)} messages on 12 "
                                    "topics)")
    again = read_mcap(copy / "run.mcap")
    assert [t for _, t, _ in again] == sorted(t for _, t, _ in again)
    assert sorted(again) == sorted(live)
    # one arm's part alone: its own run.mcap, its topics under its arm id
    result = CliRunner().invoke(app, ["report", str(copy / "B"), "--mcap"])
    assert result.exit_code == 0, result.output
    assert {topic for topic, _, _ in read_mcap(copy / "B" / "run.mcap")} >= {
        "/B/joint_states", "/seqrun/events"}
    # the HTML report: each arm's in its part; one file holds one arm (name its part)
    for arm in "AB":
        (copy / arm / "report.html").unlink(missing_ok=True)
    result = CliRunner().invoke(app, ["report", str(copy)])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines() == [
        f"wrote {copy / arm / 'report.html'}" for arm in "AB"]
    assert "arm B" in (copy / "B" / "report.html").read_text()
    result = CliRunner().invoke(app, ["report", str(copy), "--out", str(tmp_path / "r.html")])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        f"error: {copy}: a run of several arms: each arm's part is a run folder of its own "
        f"({copy / 'A'}, {copy / 'B'}): name one for --out"]


def test_no_run_mcap_when_the_campaign_turns_it_off(tmp_path, monkeypatch):
    _campaign(tmp_path, monkeypatch, ros='\n[ros]\nmcap = false\n')
    run = _run(tmp_path / "runs" / "quiet", "--virtual-time")
    assert not list(run.rglob("*.mcap*"))
    assert json.loads((run / "arms.json").read_text())["ros"] == {"mcap": None}


def test_the_merge_keeps_log_time_order_when_one_arm_lags(tmp_path):
    """Events reach the writer as their arms' threads hand them over: one arm's may come
    late (up to the merge's lag); the bag is in log-time order all the same."""
    from seqrun.arm.between_arms import base_transform
    from seqrun.service.arms_mcap import ArmsBag
    from projecttree import shipped_arm

    arm = shipped_arm()
    bag = ArmsBag(tmp_path, {"A": arm, "B": arm},
                  {a: base_transform((0, 0, 0), (0, 0, 0)) for a in "AB"}, 1000.0)

    def stream(arm_id: str) -> list[dict]:
        out = [{"t": 0.0, "type": "run_started", "start_epoch_s": 1000.0 + (arm_id == "B")
                * 0.05, "clock_s": 0.0}]
        for k in range(1, 200):
            out.append({"t": k * 0.01, "type": "setpoint", "planned_deg": [0] * 7,
                        "measured_deg": [k * 0.01] * 7, "read_t": k * 0.01 - 0.004})
            if k % 50 == 0:
                out.append({"t": k * 0.01, "type": "step_started", "step": k // 50})
        return out

    a, b = stream("A"), stream("B")
    fed = []
    for k in range(len(a) + 30):     # B handed over 30 events (0.3 s) behind A
        if k < len(a):
            fed.append(("A", a[k]))
        if 0 <= k - 30 < len(b):
            fed.append(("B", b[k - 30]))
    for arm_id, event in fed:
        bag.write_event(arm_id, event)
    path = bag.close()
    times = [t for _, t, _ in read_mcap(path)]
    assert times == sorted(times) and bag.reordered == 0
    assert len([1 for topic, _, _ in read_mcap(path) if topic == "/B/joint_states"]) == 199


def test_run_mcap_stamps_events_at_start_epoch_plus_t():
    """``start_epoch_s`` is the wall-clock time of t = 0; in real time run_started itself
    comes a moment later (its own t): an event at t is stamped start_epoch_s + t."""
    from projecttree import shipped_arm
    from seqrun.ros_messages.from_events import EventTranslator
    from seqrun.ros_messages.values import stamp_ns

    translator = EventTranslator(shipped_arm())
    started = translator.translate({"t": 0.000238, "type": "run_started",
                                    "start_epoch_s": 1000.0, "clock_s": 5.0})
    assert started[-1].log_ns == stamp_ns(1000.000238)
    (line,) = [r for r in translator.translate({"t": 1.0, "type": "step_started", "step": 1})
               if type(r).__name__ == "EventLine"]
    assert line.log_ns == stamp_ns(1001.0)
