"""What a run of two arms must leave (issue 28): read back from its run folder, the same
checks for ``seqrun run`` and for a run started from the console of several arms.

``check_one_time_base``: arms.json's one time base and each arm's start on it;
``check_b_moves_after_a_signalled`` / ``check_traces_on_the_one_time_base``: the short
sequence's events and CAN traces on that time line (twoarmskit.SHORT: B waits for A);
``check_run_mcap``: ``<run>/run.mcap`` with both arms' topics, /tf and /tf_static.
"""

from __future__ import annotations

import collections
import json
from pathlib import Path

import pytest

from seqrun.powercube.protocol import CommandId
from runfolder import RunFolder
from seqrun.service.runlog import read_trace


def events(part: Path) -> list[dict]:
    return RunFolder(part).events()


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
