"""A JointTrajectory as one continuous motion (issue 41.1): interpolated as ros2_control's
joint_trajectory_controller does (seqrun/arm/trajectory_interp.py), checked as a whole before
anything moves and run through the service layer at virtual time (seqrun ros's path)."""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np
import pytest

from seqrun.arm.description import load_arm
from seqrun.arm.trajectory_interp import TimedPoint, TrajectoryError, interpolate
from seqrun.errors import Refused
from seqrun.service.trajectories import JointTrajectory, TrajectoryPoint, run_trajectory
from test_ros_trajectory import session  # noqa: F401  (an armed, homed session at virtual time)

ROOT = Path(__file__).resolve().parents[1]
ARM = ROOT / "arms" / "lwa3.yaml"
CYCLE_S = 0.01


def smooth(start_deg: dict[str, float], count: int = 50, span_s: float = 5.0,
           reach_deg: tuple[float, float] = (20.0, 10.0)) -> JointTrajectory:
    """j1 and j2 along a minimum-jerk curve: ``count`` points over ``span_s``."""
    points = []
    for i in range(1, count + 1):
        u = i / count
        f = 10 * u**3 - 15 * u**4 + 6 * u**5
        points.append(TrajectoryPoint(
            (math.radians(start_deg["j1"] + reach_deg[0] * f),
             math.radians(start_deg["j2"] + reach_deg[1] * f)), span_s * u))
    return JointTrajectory(("j1", "j2"), tuple(points))


def events(run_dir: Path) -> list[dict]:
    with gzip.open(run_dir / "events.jsonl.gz", "rt", encoding="utf-8") as handle:
        return [json.loads(line) for line in handle]


def test_a_50_point_5_s_trajectory_runs_in_5_s_through_its_points(session):
    start = session.telemetry.joints_deg()
    trajectory = smooth(start)
    result = run_trajectory(session, trajectory, by="test").wait(timeout=120)
    assert result.ok, result.message
    log = events(result.run_dir)
    (finished,) = [e for e in log if e["type"] == "step_finished"]
    assert finished["planned_duration_s"] == pytest.approx(5.0, abs=1e-9)
    assert finished["executed_duration_s"] == pytest.approx(5.0, abs=CYCLE_S)
    assert finished["interpolation"] == "linear" and finished["points"] == 50
    # one motion: one plan, streamed without coming to rest in between
    assert len([e for e in log if e["type"] == "move_planned"]) == 1
    setpoints = {round(e["plan_t"], 6): e for e in log if e["type"] == "setpoint"}
    for point in trajectory.points:
        due = setpoints[round(point.time_from_start_s, 6)]
        for i, name in enumerate(("j1", "j2")):
            wanted = math.degrees(point.positions_rad[i])
            index = int(name[1]) - 1
            assert due["planned_deg"][index] == pytest.approx(wanted, abs=1e-3)
            assert due["measured_deg"][index] == pytest.approx(wanted, abs=0.5)
    middle = [e for e in log if e["type"] == "setpoint" and 1.0 < e["plan_t"] < 4.0]
    assert min(abs(e["planned_vel_deg_s"][0]) for e in middle) > 1.0  # never at rest
    joints = session.poll_status().joints_deg
    assert joints["j1"] == pytest.approx(start["j1"] + 20, abs=0.1)
    # the points are in the run folder's inputs/, beside the sequence
    (points,) = (result.run_dir / "inputs").rglob("ros_trajectory_*.csv")
    assert len(points.read_text(encoding="utf-8").splitlines()) == 51


def test_cubic_interpolation_passes_through_the_points_with_their_velocities():
    times = [0.5, 1.0, 1.5, 2.0]
    positions = [0.1, 0.25, 0.3, 0.2]
    velocities = [0.2, 0.15, -0.05, 0.0]
    points = [TimedPoint(t, (p, 0.0), (v, 0.0)) for t, p, v in zip(times, positions,
                                                                    velocities)]
    made = interpolate([0.0, 0.0], points, CYCLE_S, [0, 1])
    assert made.kind == "cubic"
    for t, p, v in zip(times, positions, velocities):
        row = int(np.flatnonzero(np.isclose(made.plan.times, t))[0])
        assert made.plan.positions[row, 0] == pytest.approx(p, abs=1e-12)
        assert made.velocities[row, 0] == pytest.approx(v, abs=1e-12)
        position, velocity, _ = made.plan.at(t)
        assert position[0] == pytest.approx(p, abs=1e-12)
        if t < times[-1]:  # the streamed plan's velocity (it ends at rest)
            assert velocity[0] == pytest.approx(v, abs=0.01)
    # the joint not moved stays where it stands
    assert np.all(made.plan.positions[:, 1] == 0.0)


def test_quintic_with_accelerations_and_linear_without_velocities():
    quintic = interpolate([0.0], [TimedPoint(1.0, (0.2,), (0.1,), (0.05,))], CYCLE_S, [0])
    row = len(quintic.plan.times) - 1
    assert quintic.kind == "quintic"
    assert quintic.velocities[row, 0] == pytest.approx(0.1, abs=1e-12)
    assert quintic.accelerations[row, 0] == pytest.approx(0.05, abs=1e-12)
    assert quintic.accelerations[0, 0] == pytest.approx(0.0, abs=1e-12)  # from rest
    linear = interpolate([0.0], [TimedPoint(1.0, (0.2,))], CYCLE_S, [0])
    assert linear.kind == "linear" and linear.plan.at(0.5)[0][0] == pytest.approx(0.1)


@pytest.mark.parametrize("points, reason", [
    ([TimedPoint(0.0, (0.1,))], "point 1/1 (t=0 s): time_from_start 0 but 5.730° away"),
    ([TimedPoint(1.0, (0.1,)), TimedPoint(1.0, (0.2,))],
     "point 2/2 (t=1 s): time_from_start must be after the previous point's 1 s"),
])
def test_times_must_increase_and_a_first_point_at_0_s_is_the_current_state(points, reason):
    with pytest.raises(TrajectoryError, match=reason.replace("(", r"\(").replace(")", r"\)")):
        interpolate([0.0], points, CYCLE_S, [0])


def test_a_point_beyond_a_joint_limit_is_refused_naming_the_point_and_time(session):
    start = session.telemetry.joints_deg()
    points = tuple(TrajectoryPoint((math.radians(start["j6"] + i),), float(i))
                   for i in range(1, 8))  # j6 from 115.74 by 1 a second: beyond 120 at 5 s
    sent_before = session.poll_status().joints_deg
    with pytest.raises(Refused) as caught:
        run_trajectory(session, JointTrajectory(("j6",), points), by="test")
    message = str(caught.value)
    lo, hi = load_arm(ARM).joint("j6").limits_deg
    first = next(i for i, p in enumerate(points, 1)
                 if not lo <= math.degrees(p.positions_rad[0]) <= hi)
    assert first == 5
    assert message.startswith(f"trajectory point {first}/7 (t={first} s): j6 at ")
    assert "outside its limits" in message and "\n" not in message
    assert session.activity is None and session.poll_status().joints_deg == sent_before


def test_a_too_fast_segment_is_refused_naming_the_point_and_time(session):
    start = session.telemetry.joints_deg()
    points = (TrajectoryPoint((math.radians(start["j1"] + 2),), 1.0),
              TrajectoryPoint((math.radians(start["j1"] + 4),), 2.0),
              TrajectoryPoint((math.radians(start["j1"] + 34),), 3.0))  # 30°/s: the limit
    with pytest.raises(Refused) as caught:
        run_trajectory(session, JointTrajectory(("j1",), points), by="test")
    message = str(caught.value)
    assert message.startswith("trajectory point 3/3 (t=3 s): j1 velocity ")
    assert "above its limit" in message and session.activity is None


def test_a_trajectory_while_one_runs_is_refused(session):
    start = session.telemetry.joints_deg()
    running = run_trajectory(session, smooth(start, count=10, span_s=2.0), by="test")
    with pytest.raises(Refused, match="another motion is running"):
        run_trajectory(session, smooth(start, count=5, span_s=1.0), by="test")
    assert running.wait(timeout=120).ok


def test_move_trajectory_runs_a_csv_file_in_a_sequence(tmp_path):
    from seqrun.service.checking import check_sequence

    rows = ["t,j1,j2"] + [f"{0.1 * i:.1f},{0.4 * i},{-90 + 0.2 * i}" for i in range(1, 51)]
    (tmp_path / "wave.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    sequence = tmp_path / "wave.yaml"
    sequence.write_text("name: wave\nsteps:\n  - move_trajectory: {file: wave.csv}\n",
                        encoding="utf-8")
    start = {"j1": 0.0, "j2": -90.0, "j3": 0.0, "j4": -120.32, "j5": 0.0, "j6": 115.74,
             "j7": 0.0}
    check = check_sequence(sequence, start_deg=start, started=True, arm_file=ARM,
                           dry_run=False)
    assert not check.errors, check.errors
    (tmp_path / "wave.csv").write_text("t,j1\n1.0,5\n0.5,6\n", encoding="utf-8")
    check = check_sequence(sequence, start_deg=start, started=True, arm_file=ARM,
                           dry_run=False)
    assert [str(e) for e in check.errors] and "point 2/2 (t=0.5 s)" in str(check.errors[0])
    assert "wave.yaml:3:" in str(check.errors[0])


def test_a_dense_moveit_style_trajectory_with_velocities_runs_as_planned(session):
    """More points than the old limit (500), a first point at 0 s from a reading of the
    joints (0.05° off the measured state), velocities on every point: cubic."""
    start = session.telemetry.joints_deg()
    count, span_s = 601, 6.0
    points = []
    for i in range(count):
        u = i / (count - 1)
        f = 10 * u**3 - 15 * u**4 + 6 * u**5
        df = (30 * u**2 - 60 * u**3 + 30 * u**4) / span_s
        offset = 0.05 if i == 0 else 0.0
        points.append(TrajectoryPoint((math.radians(start["j1"] + 30 * f + offset),),
                                      span_s * u, (math.radians(30 * df),)))
    result = run_trajectory(session, JointTrajectory(("j1",), tuple(points)),
                            by="test").wait(timeout=120)
    assert result.ok, result.message
    (finished,) = [e for e in events(result.run_dir) if e["type"] == "step_finished"]
    assert finished["interpolation"] == "cubic" and finished["points"] == count
    assert finished["executed_duration_s"] == pytest.approx(span_s, abs=CYCLE_S)
    assert session.poll_status().joints_deg["j1"] == pytest.approx(start["j1"] + 30, abs=0.1)


def test_a_first_point_at_0_s_away_from_the_arm_is_refused(session):
    start = session.telemetry.joints_deg()
    points = (TrajectoryPoint((math.radians(start["j1"] + 3),), 0.0),
              TrajectoryPoint((math.radians(start["j1"] + 4),), 1.0))
    with pytest.raises(Refused, match=r"^trajectory point 1/2 \(t=0 s\): time_from_start 0 "
                                      r"but 3\.000° away"):
        run_trajectory(session, JointTrajectory(("j1",), points), by="test")


def test_after_a_step_that_loses_the_arm_only_the_points_file_is_checked(tmp_path):
    from seqrun.service.checking import check_sequence

    (tmp_path / "far.csv").write_text("t,j1\n1.0,170\n", encoding="utf-8")  # too fast
    sequence = tmp_path / "far.yaml"
    # the first refused: where the arm stands after it is not known, the second's motion
    # (as fast) is not checked from a place the arm would not be
    sequence.write_text("name: far\nsteps:\n  - move_trajectory: {file: far.csv}\n"
                        "  - move_trajectory: {file: far.csv}\n", encoding="utf-8")
    start = {"j1": 0.0, "j2": -90.0, "j3": 0.0, "j4": -120.32, "j5": 0.0, "j6": 115.74,
             "j7": 0.0}
    check = check_sequence(sequence, start_deg=start, started=True, arm_file=ARM,
                           dry_run=False)
    assert [e.line for e in check.errors] == [3], [str(e) for e in check.errors]
