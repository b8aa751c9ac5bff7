"""What a two-arm run leaves behind (issue 28, item 3): both arms on ONE time base
(``arms.json`` gives each arm's start on the run clock and the wall clock; events and CAN
traces of both arms lie on one time line), and one ``<run>/run.mcap`` with both arms'
topics namespaced by arm id, stamped on that time base, in log-time order."""

from __future__ import annotations

import collections
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from seqrun.cli import app
from seqrun.powercube.protocol import CommandId
from seqrun.service.runlog import read_trace
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


def events(part: Path) -> list[dict]:
    return [json.loads(line) for line in (part / "events.jsonl").read_text().splitlines()]


def on_run_clock(run: Path, arm: str) -> list[tuple[float, dict]]:
    """The arm's events at their time on the run's one clock (arms.json's rule)."""
    start = json.loads((run / "arms.json").read_text())["arms"][arm]["start"]["clock_s"]
    return [(round(start + e["t"], 6), e) for e in events(run / arm)]


def step_of(timed, label: str, phase: str = "step_finished") -> tuple[float, dict]:
    """When the step labelled ``label`` started or finished (``phase``)."""
    step = next(e["step"] for _, e in timed
                if e["type"] == "step_started" and e["label"] == label)
    return next((t, e) for t, e in timed if e["type"] == phase and e.get("step") == step)


# -- one time base ----------------------------------------------------------------------------
def check_one_time_base(run: Path) -> None:
    summary = json.loads((run / "arms.json").read_text())
    base = summary["time_base"]
    assert base["clock"] in ("monotonic", "virtual")
    for arm in "AB":
        start = summary["arms"][arm]["start"]
        report = json.loads((run / arm / "report.json").read_text())
        started = next(e for e in events(run / arm) if e["type"] == "run_started")
        # the arm's start as its own records give it ...
        assert start["clock_s"] == report["clock_s"] == started["clock_s"]
        assert start["epoch_s"] == report["start_epoch_s"] == started["start_epoch_s"]
        # ... and on the run's one mapping of the run clock to the wall clock
        assert start["epoch_s"] == pytest.approx(
            base["epoch_s"] + start["clock_s"] - base["clock_s"], abs=2e-6)
        assert start["after_s"] == pytest.approx(start["clock_s"] - base["clock_s"], abs=2e-6)
        assert start["after_s"] >= 0
    assert summary["arms"]["B"]["base"] == {"position_mm": [0.0, 900.0, 0.0],
                                            "rpy_deg": [0.0, 0.0, 180.0]}


def check_b_moves_after_a_signalled(run: Path) -> float:
    a, b = on_run_clock(run, "A"), on_run_clock(run, "B")
    signalled, _ = step_of(a, "signal A_turned")
    waiting, _ = step_of(b, "wait for A_turned", "step_started")
    waited, _ = step_of(b, "wait for A_turned")
    b_moves, _ = step_of(b, "move j1 to -10°", "step_started")
    assert waiting < signalled, "B did not wait: the test would prove nothing"
    assert signalled <= waited <= b_moves
    return signalled


def motion_frames(run: Path, arm: str) -> list[float]:
    """The SetMotion requests of the arm's CAN trace, on the run clock (arms.json's rule:
    a trace stamp s is the reading ``s - epoch_s + clock_s``)."""
    base = json.loads((run / "arms.json").read_text())["time_base"]
    return [round(m.timestamp - base["epoch_s"] + base["clock_s"], 6)
            for m in read_trace(run / arm)
            if not m.is_rx and m.data and m.data[0] == CommandId.SET_MOTION]


def check_traces_on_the_one_time_base(run: Path, signalled: float) -> None:
    a, b = motion_frames(run, "A"), motion_frames(run, "B")
    waiting, _ = step_of(on_run_clock(run, "B"), "wait for A_turned", "step_started")
    a_moved, _ = step_of(on_run_clock(run, "A"), "move j1 to 10°", "step_started")
    assert a and min(a) >= a_moved and any(t < signalled for t in a)
    # B's trace: nothing moves it while it waits for A's signal, then its move streams
    assert not [t for t in b if waiting <= t < signalled]
    assert [t for t in b if t > signalled]


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
def read_mcap(path: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time, data) in the order written."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        return [(c.topic, m.log_time, bytes(m.data))
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


def check_run_mcap(run: Path) -> None:
    from rosbags.highlevel import AnyReader

    from seqrun.ros_messages.values import stamp_ns

    path = run / "run.mcap"
    assert path.is_file() and not (run / "A" / "run.mcap").exists()
    written = read_mcap(path)
    times = [t for _, t, _ in written]
    assert times == sorted(times), "run.mcap is not in log-time order"
    with AnyReader([path]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        for arm in "AB":
            assert topics[f"/{arm}/joint_states"] == "sensor_msgs/msg/JointState"
            assert topics[f"/{arm}/events"] == "std_msgs/msg/String"
            assert f"/{arm}/planned" in topics and f"/{arm}/markers" in topics
        by_topic = collections.defaultdict(list)
        for connection, log_time, raw in reader.messages():
            by_topic[connection.topic].append(
                (log_time, reader.deserialize(raw, connection.msgtype)))
    for arm in "AB":
        part = events(run / arm)
        started = next(e for e in part if e["type"] == "run_started")
        start = started["start_epoch_s"]
        logged = [e for e in part if e["type"] not in ("setpoint", "measurement")]
        got = [(t, json.loads(m.data)) for t, m in by_topic[f"/{arm}/events"]]
        assert [e for _, e in got] == logged                    # every event, exactly
        # each at start_epoch_s + t; those before run_started (the zero reference: timed
        # from the executor's making) with run_started
        early = part.index(started)
        assert [t for t, _ in got] == [stamp_ns(start + (started if k < early else e)["t"])
                                       for k, e in enumerate(logged)]
        states = by_topic[f"/{arm}/joint_states"]
        setpoints = [e for e in part if e["type"] == "setpoint"]
        assert len(states) >= len(setpoints) > 0
        stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in states]
        assert stamps == sorted(stamps)
        assert all(m.name == ["j1", "j2", "j3", "j4", "j5", "j6", "j7"] for _, m in states)
    frames = {tf.child_frame_id: tf for _, m in by_topic["/tf_static"] for tf in m.transforms}
    assert {tf.header.frame_id for tf in frames.values()} == {"facility"}
    b = frames["B/base"].transform
    assert (b.translation.x, b.translation.y, b.translation.z) == pytest.approx((0, 0.9, 0))
    assert abs(b.rotation.z) == pytest.approx(1.0)              # turned 180° about z
    children = {tf.child_frame_id for _, m in by_topic["/tf"] for tf in m.transforms}
    assert {"A/j1", "A/end_effector", "B/j1", "B/end_effector"} <= children


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
    # the HTML report draws one arm: the run's folder says which parts there are
    result = CliRunner().invoke(app, ["report", str(copy)])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        f"error: {copy}: a run of several arms: each arm's part is a run folder of its own "
        f"({copy / 'A'}, {copy / 'B'}); --mcap writes the run's one run.mcap of every arm"]


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
