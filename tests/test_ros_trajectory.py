"""A joint trajectory from ROS 2 becomes a checked sequence (seqrun/service/trajectories.py),
without ROS: the points file of its one move_trajectory step, every refusal (one line,
nothing sent), the desk
found on the path the move will really follow, and a run on the simulator at virtual time.
And the chain as /tf's tree of frames (seqrun/service/kinematics.py: link_transforms)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.errors import Refused
from seqrun.powercube.protocol import BROADCAST_ID
from seqrun.service import ArmSession
from seqrun.service.connection import open_connection
from seqrun.service.kinematics import end_effector, link_transforms
from seqrun.service.trajectories import (MAX_POINTS, JointTrajectory, TrajectoryPoint,
                                         check_trajectory, run_trajectory, trajectory_csv)

ROOT = Path(__file__).resolve().parents[1]
ARM = ROOT / "arms" / "lwa3.yaml"
PARK = {"j1": 0.0, "j2": -90.0, "j3": 0.0, "j4": -120.32, "j5": 0.0, "j6": 115.74, "j7": 0.0}


def trajectory(names, *points) -> JointTrajectory:
    """points: (degrees..., time_from_start_s)."""
    return JointTrajectory(tuple(names), tuple(
        TrajectoryPoint(tuple(math.radians(d) for d in p[:-1]), p[-1]) for p in points))


def test_the_points_are_written_in_user_degrees_with_their_times(arm):
    text = trajectory_csv(arm, trajectory(("j1", "j2"), (10, -80, 2.0), (10, -70, 4.0)))
    rows = [r.split(",") for r in text.splitlines()]
    assert rows[0] == ["t", "j1", "j2"] and len(rows) == 3
    assert [float(x) for x in rows[1]] == pytest.approx([2.0, 10.0, -80.0], abs=1e-12)
    assert [float(x) for x in rows[2]] == pytest.approx([4.0, 10.0, -70.0], abs=1e-12)


def test_velocities_and_accelerations_are_written_when_every_point_gives_them(arm):
    points = (TrajectoryPoint((0.1,), 1.0, (0.2,), (0.3,)),
              TrajectoryPoint((0.2,), 2.0, (0.0,), (0.0,)))
    text = trajectory_csv(arm, JointTrajectory(("j1",), points))
    rows = [r.split(",") for r in text.splitlines()]
    assert rows[0] == ["t", "j1", "j1_vel", "j1_acc"]
    assert float(rows[1][2]) == pytest.approx(math.degrees(0.2))
    only_some = (points[0], TrajectoryPoint((0.2,), 2.0))
    assert trajectory_csv(arm, JointTrajectory(("j1",), only_some)).startswith("t,j1\n")


def test_the_locked_joint_at_its_locked_value_is_accepted(arm):
    text = trajectory_csv(arm, trajectory(("j1", "j3"), (5, 0, 1.0)))
    assert text.splitlines()[0] == "t,j1,j3"


@pytest.mark.parametrize("bad, reason", [
    (trajectory(("j1", "j3"), (5, 4, 1.0)), "j3 is locked at 0° in the arm file"),
    (trajectory(("j9",), (5, 1.0)), "unknown joint 'j9'"),
    (trajectory(("j1", "j1"), (5, 5, 1.0)), "j1 is named twice"),
    (trajectory(("j1",)), "no points"),
    (trajectory((), (1.0,)), "no joint names"),
    (trajectory(("j1",), (5, 2.0), (6, 1.0)),
     "point 2/2 (t=1 s): time_from_start must be after the previous point's 2 s"),
    (trajectory(("j1",), (5, 2.0), (6, 2.0)), "point 2/2 (t=2 s): time_from_start must be"),
    (trajectory(("j1",), (float("nan"), 1.0)),
     "point 1/1 (t=1 s): j1: nan is not a finite number"),
    (JointTrajectory(("j1", "j2"), (TrajectoryPoint((0.1,), 1.0),)),
     "point 1/1 (t=1 s): 1 positions for 2 joints"),
    (JointTrajectory(("j1",), (TrajectoryPoint((True,), 1.0),)), "True is not a number"),
    (JointTrajectory(("j1",), tuple(TrajectoryPoint((0.0,), float(i))
                                    for i in range(1, MAX_POINTS + 2))), "at most 10000"),
])
def test_bad_trajectories_are_refused_in_one_line(arm, bad, reason):
    with pytest.raises(Refused) as caught:
        trajectory_csv(arm, bad)
    assert reason in str(caught.value) and "\n" not in str(caught.value)


# ---------------------------------------------------------------------- on the session
@pytest.fixture
def session(tmp_path):
    connection = open_connection(force_sim=True, clock=VirtualClock())
    s = ArmSession(load_arm(ARM), connection, status_hz=0, log_root=tmp_path / "runs",
                   poses_dir=ROOT / "poses")
    s.poll_status()
    assert s.arm_up().ok and s.home().ok
    s.poll_status()
    yield s
    s.close()


def motion_frames(session: ArmSession) -> list:
    sent: list = []
    session.client.add_frame_listener(
        lambda msg: sent.append(msg) if (not msg.is_rx and msg.arbitration_id != BROADCAST_ID
                                         and bytes(msg.data)[:1] == b"\x0b") else None)
    return sent


def test_a_trajectory_into_the_desk_is_refused_on_its_planned_path_and_moves_nothing(session):
    sent = motion_frames(session)
    into_the_desk = trajectory(("j2",), (-110, 2.0))  # j2 within its limits: the hand hits it
    with pytest.raises(Refused) as caught:
        run_trajectory(session, into_the_desk, by="test")
    message = str(caught.value)
    assert message.startswith("trajectory point 1/1 (t=2 s): ") and "desk" in message
    assert "trajectory" in message and "ros_trajectory" not in message
    assert sent == [] and session.activity is None


def test_a_point_outside_the_limits_is_refused_naming_the_point(session):
    # the first sample beyond -120° (the point itself, -135° at 4 s, is later)
    with pytest.raises(Refused, match=r"^trajectory point 2/2 \(t=4 s\): j2 at -120\.\d+° at "
                                      r"t=3\.\d+ s, outside its limits -120°\.\.120°"):
        run_trajectory(session, trajectory(("j2",), (-80, 1.0), (-135, 4.0)))


def test_a_trajectory_is_refused_while_the_arm_is_halted(session):
    session.halt("test")
    with pytest.raises(Refused, match="trajectory: the arm is halted"):
        run_trajectory(session, trajectory(("j1",), (5, 1.0)))


def test_a_valid_trajectory_runs_as_a_sequence_with_its_run_folder(session):
    sent = motion_frames(session)
    check, file = check_trajectory(session, trajectory(("j1", "j2"), (10, -80, 1.0),
                                                       (20, -70, 2.0)))
    assert check.valid and len(check.loaded.steps) == 1 and file.is_file()
    assert check.loaded.steps[0].kind == "move_trajectory"
    activity = run_trajectory(session, trajectory(("j1", "j2"), (10, -80, 1.0),
                                                  (20, -70, 2.0)), by="test")
    result = activity.wait(timeout=60)
    assert result.ok and result.run_dir is not None
    assert (result.run_dir / "events.jsonl.gz").is_file()
    assert sent  # it moved
    joints = session.poll_status().joints_deg
    assert joints["j1"] == pytest.approx(20, abs=0.1)
    assert joints["j2"] == pytest.approx(-70, abs=0.1)


# ---------------------------------------------------------------------- /tf's frames
@pytest.mark.parametrize("joints", [list(PARK.values()), [0.0] * 7,
                                    [10, -30, 0, 40, -20, 60, 90]])
def test_the_link_transforms_compose_to_the_end_effector(arm, joints):
    frames = link_transforms(arm, joints, "lwa3/")
    assert [f[1] for f in frames] == ["lwa3/j1", "lwa3/j2", "lwa3/j3", "lwa3/j4", "lwa3/j5",
                                      "lwa3/j6", "lwa3/j7", "lwa3/end_effector"]
    assert frames[0][0] == "lwa3/base" and all(a[1] == b[0] for a, b in zip(frames, frames[1:]))
    total = np.eye(4)
    for _, _, xyz, (x, y, z, w) in frames:
        assert math.isclose(x * x + y * y + z * z + w * w, 1.0, abs_tol=1e-9) and w >= 0
        rotation = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        step = np.eye(4)
        step[:3, :3], step[:3, 3] = rotation, xyz
        total = total @ step
    expected = end_effector(arm, joints)["position_mm"]
    assert total[:3, 3] * 1000 == pytest.approx(expected, abs=1e-3)


def test_the_runs_own_messages_name_the_trajectory_not_its_private_file():
    from seqrun.service.trajectories import in_trajectory_terms

    message = ("not valid from the arm's measured state: /tmp/seqrun-trajectories-q4dt1f0u/"
               "ros_trajectory_12.yaml:4:5: move before home: the modules refuse motion")
    assert in_trajectory_terms(message) == ("not valid from the arm's measured state: "
                                            "trajectory: move before home: the modules "
                                            "refuse motion")
