"""The zero reference: the modules' zeros are where they were powered off.

Power-off poses and their offsets in the arm file, the power_off step, the record, and the
run-start decision: shown, confirmed on real hardware after a power-on, refused without a
record. The simulator powers on at any supported pose; "real hardware" here is a
connection that is not the built-in simulator (as a socketcand bus to `seqrun sim serve`).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT, shipped_arm
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.cli.app import app
from seqrun.cli.zero import zero_at_run_start
from seqrun.clock import VirtualClock
from seqrun.service.connection import Connection, open_connection
from seqrun.errors import UserInputError
from seqrun.results import EXIT_OK
from seqrun.arm.poses import find_pose, load_pose
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.sim.bus import SimBus
from seqrun.sequence.validation import validate_sequence
from seqrun.service.zero import ZeroStore, zero_for_run
from seqrun.drivers.base import ArmIdentity
from seqrun.drivers.powercube.units import to_module_rad, to_user_deg

ARM = shipped_arm()
PARK_OFFSETS = {"j1": 0, "j2": 90, "j3": 0, "j4": 120.32, "j5": 0, "j6": -115.74, "j7": 0}
OPSAFE = [70, 30, 0, 70, 20, 50, 0]


@pytest.fixture(autouse=True)
def state_dir(tmp_path, monkeypatch):
    folder = tmp_path / "state"
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(folder))
    return folder


#: The serial numbers of the tests' "real" arm (one physical arm, powered on again and again).
SERIALS = {m: 4_200_000 + m for m in range(1, 8)}


def hardware(clock=None, channel="hw", serials=SERIALS) -> Connection:
    """A simulated arm (the one with ``serials``) behind a connection seqrun treats as
    real hardware."""
    clock = clock or VirtualClock()
    bus = SimBus(channel=f"{channel}-{id(clock)}", clock=clock, serials=serials)
    return Connection(bus, clock, False, "test bus (treated as real hardware)")


def store_of(serials=SERIALS) -> ZeroStore:
    """The zero-reference store of the arm with ``serials`` on this (test) machine."""
    return ZeroStore(ArmIdentity.of(serials))


def motion_frames(frames):
    return [f for f in frames if not f.is_rx and 0x0E1 <= f.arbitration_id <= 0x0FF
            and f.data[:1] == b"\x0b"]


# --------------------------------------------------------------------------- arm file
def test_park_offsets_are_the_thesis_table_and_totem_offsets_are_zero():
    assert ARM.default_power_off == "park"
    assert ARM.power_off_pose("park").offsets_deg == pytest.approx(PARK_OFFSETS)
    assert [j.offset_deg for j in ARM.joints] == pytest.approx(list(PARK_OFFSETS.values()))
    assert set(ARM.power_off_pose("totem").offsets_deg.values()) == {0.0}


@pytest.mark.parametrize("pose", ["park", "totem"])
def test_a_power_off_pose_is_where_every_module_reads_zero(pose):
    """user = -offset at the power-off pose: the shipped pose files agree."""
    stored = load_pose(find_pose(pose, ROOT / "poses")).joints_deg
    assert ARM.power_off_joints_deg(pose) == pytest.approx(stored)
    zeroed = ARM.with_zero_reference(pose)
    assert [to_module_rad(j, stored[j.name]) for j in zeroed.joints] == pytest.approx([0.0] * 7)


def test_an_unknown_power_off_pose_names_the_known_ones():
    with pytest.raises(UserInputError, match="power-off poses: park, totem"):
        ARM.with_zero_reference("opsafe")


def test_the_joints_offsets_must_be_those_of_the_default_power_off(tmp_path):
    from seqrun.errors import SequenceInvalid

    text = (ROOT / "arms" / "lwa3.yaml").read_text().replace("default_power_off: park",
                                                              "default_power_off: totem")
    (tmp_path / "arm.yaml").write_text(text)
    with pytest.raises(SequenceInvalid, match="offset_deg must be those of default_power_off"):
        load_arm(tmp_path / "arm.yaml")


# --------------------------------------------------------------------------- executor offsets
@pytest.mark.parametrize("zero", ["park", "totem"])
def test_the_run_converts_with_the_offsets_of_the_zero_in_force(zero):
    """The same sequence sends the module positions of the zero reference in force."""
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    arm = ARM.with_zero_reference(zero)
    connection = open_connection(force_sim=True, clock=VirtualClock(), power_on_pose=zero)
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=None, confirm=lambda q: True)
        positions = connection.bus.arm.positions()
    finally:
        connection.close()
    assert outcome.result.exit_code == EXIT_OK
    offsets = ARM.power_off_pose(zero).offsets_deg
    expected = [math.radians(q + offsets[j.name]) for q, j in zip(OPSAFE, ARM.joints)]
    assert list(positions.values()) == pytest.approx(expected, abs=math.radians(0.25))


# --------------------------------------------------------------------------- power_off step
def test_shutdown_records_totem_through_the_power_off_step(state_dir):
    loaded = load_sequence(ROOT / "sequences" / "shutdown.yaml")
    store = store_of()
    connection = hardware()

    def attach(executor):
        executor.record_zero = lambda pose: str(store.set_record(
            pose, by="shutdown.yaml", joints_deg=ARM.power_off_joints_deg(pose)))
    try:
        outcome = run_sequence(loaded, ARM, connection, log_dir=None, confirm=lambda q: True,
                               on_executor=attach)
    finally:
        connection.close()
    assert outcome.result.exit_code == EXIT_OK
    assert store.record.pose == "totem" and store.record.by == "shutdown.yaml"
    assert store.path.parent == state_dir / "arms"
    assert "recorded 20" in store.record.describe("Totem")


def test_power_off_away_from_the_pose_aborts_and_records_nothing(tmp_path):
    """The step measures: an arm that is not there (validation assumed it would be) ends
    the run as a fault, nothing recorded."""
    from seqrun.errors import RunAborted
    from seqrun.service.runner import build_executor
    from seqrun.steps import power_off

    loaded = load_sequence(ROOT / "sequences" / "shutdown.yaml")
    step = next(s for s in loaded.steps if s.kind == "power_off")
    connection = open_connection(force_sim=True, clock=VirtualClock())  # at Park, not Totem
    recorded = []
    try:
        executor, client = build_executor(loaded, ARM, connection)
        executor.record_zero = recorded.append
        with pytest.raises(RunAborted) as info:
            power_off.run(step, executor)
        client.close()
    finally:
        connection.close()
    assert info.value.cause == "power_off"
    assert "the arm is not in totem (j2 -90.00°, j4 -120.32°, j6 +115.74° away" in str(info.value)
    assert recorded == []


def test_validation_checks_power_off_pose_position_and_no_motion_after(tmp_path):
    seq = tmp_path / "sequences" / "bad.yaml"
    seq.parent.mkdir()
    (tmp_path / "sequences" / "startup.yaml").write_text(
        (ROOT / "sequences" / "startup.yaml").read_text())
    seq.write_text("name: Bad\ndescription: three power_off mistakes\nsteps:\n"
                   "  - include: startup.yaml\n  - power_off: opsafe\n"
                   "  - power_off: totem\n  - move: totem\n")
    loaded = load_sequence(seq, project_root=ROOT)
    errors = [str(e) for e in validate_sequence(loaded, ARM).errors]
    assert any(e.endswith(":5:16: 'opsafe' is not a power-off pose of arm "
                          "'Schunk LWA 3 (RV&D facility)' (its power-off poses: park, totem; "
                          "power_off_poses in the arm file)") for e in errors), errors
    assert any(":6:5: this power_off cannot pass" in e and "j2 -90° (pose 0°)" in e
               for e in errors), errors
    assert any(":7:5: move after power_off" in e for e in errors), errors


# --------------------------------------------------------------------------- run start
def test_the_built_in_simulator_needs_no_record_its_power_on_pose_is_the_zero():
    for pose in ("park", "totem"):
        connection = open_connection(force_sim=True, clock=VirtualClock(), power_on_pose=pose)
        shown = []
        try:
            zero = zero_at_run_start(connection, ARM, lambda q: False, shown.append)
        finally:
            connection.close()
        assert zero.pose == pose and zero.question is None
        assert shown == [f"zero: {pose.capitalize()} (the simulator's power-on pose)"]


def test_real_hardware_without_a_record_refuses_with_the_command_that_sets_one(state_dir):
    connection = hardware()
    try:
        with pytest.raises(UserInputError) as info:
            zero_at_run_start(connection, ARM, lambda q: True, print)
    finally:
        connection.close()
    assert "no zero reference recorded for this arm (serials 1:4200001" in str(info.value)
    assert "'seqrun zero set POSE' on its bus (POSE: park, totem" in str(info.value)
    assert str(state_dir) in str(info.value)


def test_after_a_power_on_the_record_is_shown_and_confirmed_then_in_use(state_dir):
    store = store_of()
    store.set_record("totem", by="shutdown.yaml", joints_deg=ARM.power_off_joints_deg("totem"))
    connection = hardware()
    questions, shown = [], []
    try:
        zero = zero_at_run_start(connection, ARM,
                                 lambda q: questions.append(q) or True, shown.append)
    finally:
        connection.close()
    assert zero.pose == "totem"
    assert shown[0].startswith("zero: Totem, recorded ") and "by shutdown.yaml" in shown[0]
    assert questions and "stand in Totem now (j1 0°, j2 0°" in questions[0]
    assert store.in_use.record == store.record and store.in_use.session_mark is not None


def test_the_zero_in_use_stays_while_the_modules_hold_its_mark_even_after_a_new_record():
    """power_off records Totem while the modules stay on: their zeros do not move. HOME_OK
    plays no part: only the power-session mark the modules hold says they stayed on."""
    store = store_of()
    store.set_in_use(store.set_record("park", by="test",
                                      joints_deg=ARM.power_off_joints_deg("park")), 7)
    store.set_record("totem", by="shutdown.yaml", joints_deg=ARM.power_off_joints_deg("totem"))
    zero = zero_for_run(ARM, store, simulator_pose=None, session_mark=7)
    assert zero.pose == "park" and zero.question is None and zero.session_mark == 7
    assert store.in_use is not None
    assert zero_for_run(ARM, store, simulator_pose=None, session_mark=8).pose == "totem"
    assert store.in_use is None  # the stale entry is cleared, not kept for later


def _run_after_power_on_at_totem(record: str, answer: bool):
    """The arm was powered off (and on) in Totem; the record says ``record``."""
    store_of().set_record(record, by="test", joints_deg=ARM.power_off_joints_deg(record))
    clock = VirtualClock()
    connection = hardware(clock)
    sent = []
    try:
        zero = zero_at_run_start(connection, ARM, lambda q: answer, print)
        loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
        outcome = run_sequence(loaded, ARM.with_zero_reference(zero.pose), connection,
                               log_dir=None, confirm=lambda q: True,
                               on_executor=lambda ex: ex.client.add_frame_listener(sent.append))
        physical = np.degrees(list(connection.bus.arm.positions().values()))  # totem: user
    finally:
        connection.close()
    return outcome, physical, sent


def test_a_start_up_after_a_shutdown_at_totem_reaches_opsafe():
    outcome, physical, _ = _run_after_power_on_at_totem("totem", answer=True)
    assert outcome.result.exit_code == EXIT_OK
    assert physical == pytest.approx(OPSAFE, abs=0.25)


def test_a_wrong_record_is_stopped_by_the_confirm_before_anything_moves():
    store_of().set_record("park", by="test", joints_deg=ARM.power_off_joints_deg("park"))
    connection = hardware()
    sent = []
    connection.bus.arm  # the arm stands in Totem, its modules read zero there
    try:
        with pytest.raises(typer.Exit) as info:
            zero_at_run_start(connection, ARM, lambda q: False, sent.append)
        positions = connection.bus.arm.positions()
    finally:
        connection.close()
    assert info.value.exit_code == 130
    assert "Not started" in sent[-1]
    assert list(positions.values()) == [0.0] * 7


def test_without_the_confirm_a_wrong_record_would_drive_the_arm_into_itself():
    """Why the confirm exists: nothing else sees the wrong zero. The run 'passes' (the
    checkpoint uses the same wrong offsets) while the real arm ends with j4 at 190°, far
    beyond the ±120° where the links collide; no guard or check stops it."""
    outcome, physical, sent = _run_after_power_on_at_totem("park", answer=True)
    assert outcome.result.exit_code == EXIT_OK
    assert physical[3] == pytest.approx(70 + 120.32, abs=0.25)
    assert motion_frames(sent)


# --------------------------------------------------------------------------- CLI
@pytest.fixture
def served_arm():
    """The tests' arm served over socketcand in this process: ``-i socketcand`` options."""
    from seqrun.clock import RealClock
    from seqrun.sim.arm import SimArm
    from seqrun.sim.network import SimNetwork
    from seqrun.sim.socketcand import SocketcandServer

    clock = RealClock()
    arm = SimArm(clock, serials=SERIALS)
    with SocketcandServer(SimNetwork(clock, arm, spin_window=0.0), port=0) as server:
        server.start()
        yield ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={server.port}"]


def test_zero_set_asks_and_show_prints_the_record(state_dir, served_arm):
    runner = CliRunner()
    arm = ["--arm", str(ROOT / "arms" / "lwa3.yaml")]
    declined = runner.invoke(app, ["zero", "set", "totem", *arm, *served_arm], input="n\n")
    assert declined.exit_code == 130 and not any(state_dir.rglob("*.json"))
    accepted = runner.invoke(app, ["zero", "set", "totem", *arm, *served_arm], input="y\n")
    assert accepted.exit_code == 0, accepted.output
    assert "(serials 1:4200001, 2:4200002" in accepted.output
    assert "was powered off in Totem (j1 0°" in accepted.output
    shown = runner.invoke(app, ["zero", "show", *arm, *served_arm])
    assert "record   Totem, recorded " in shown.output and "by seqrun zero set" in shown.output
    data = json.loads(next(state_dir.glob("arms/arm-*.json")).read_text())
    assert data["record"]["pose"] == "totem" and data["record"]["user"]
    assert data["arm"]["serials"] == {str(m): str(s) for m, s in SERIALS.items()}
    listed = runner.invoke(app, ["zero", "show", *arm])  # no bus: every arm of this machine
    assert listed.exit_code == 0, listed.output
    assert "serials 1:4200001" in listed.output and "record Totem, recorded" in listed.output


def test_zero_set_of_an_unknown_pose_is_one_line():
    result = CliRunner().invoke(app, ["zero", "set", "upside-down", "--yes", "--arm",
                                      str(ROOT / "arms" / "lwa3.yaml")])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        "error: 'upside-down' is not a power-off pose of arm 'Schunk LWA 3 (RV&D facility)' "
        "(its power-off poses: park, totem)"]


def test_run_on_the_simulator_powered_on_at_totem_shows_and_uses_that_zero(tmp_path):
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"), "--yes",
                                      "--virtual-time", "--plain", "--power-on-at", "totem",
                                      "--no-report", "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    assert "zero: Totem (the simulator's power-on pose)" in result.output
    report = RunFolder(tmp_path / "run").report()
    assert report["zero"]["pose"] == "totem" and report["zero"]["source"] == "simulator"


def test_power_on_at_an_unknown_pose_is_one_line(tmp_path):
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"), "--yes",
                                      "--virtual-time", "--power-on-at", "opsafe",
                                      "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == 2
    assert "is not a power-off pose" in result.output


def test_status_and_pose_save_read_positions_with_the_recorded_zero():
    """After a power-off in Totem the modules read 0 there: with the record the arm reads
    as Totem (all zeros), not as Park."""
    from seqrun.cli.zero import zero_for_reading

    connection = hardware()
    try:
        arm, text = zero_for_reading(connection, ARM)
        assert "zero: unknown (no zero reference recorded" in text
        assert [j.offset_deg for j in arm.joints] == [j.offset_deg for j in ARM.joints]
        store_of().set_record("totem", by="shutdown.yaml",
                              joints_deg=ARM.power_off_joints_deg("totem"))
        arm, text = zero_for_reading(connection, ARM)
    finally:
        connection.close()
    assert text.startswith("zero: Totem, recorded ") and "not yet confirmed" in text
    assert [to_user_deg(j, 0.0) for j in arm.joints] == [0.0] * 7


def test_every_campaign_shares_the_arms_one_record(tmp_path, state_dir, served_arm):
    """Recorded from campaign A, the record is the arm's: campaign B (and no campaign) use
    it; nothing is written into a campaign."""
    for name in ("a", "b"):
        assert CliRunner().invoke(app, ["init", str(tmp_path / name)]).exit_code == 0
    result = CliRunner().invoke(app, ["zero", "set", "totem", "--yes", "--project",
                                      str(tmp_path / "a"), *served_arm])
    assert result.exit_code == 0, result.output
    shown = CliRunner().invoke(app, ["zero", "show", "--project", str(tmp_path / "b"),
                                     *served_arm])
    assert shown.exit_code == 0 and "record   Totem, recorded " in shown.output, shown.output
    connection = hardware()
    try:
        zero = zero_at_run_start(connection, ARM, lambda q: True, print)
    finally:
        connection.close()
    assert zero.pose == "totem" and zero.store.path.parent == state_dir / "arms"
    assert not any((tmp_path / c / ".seqrun" / "zero.json").exists() for c in "ab")


def test_an_older_per_type_record_is_named_but_never_used(state_dir, tmp_path, monkeypatch):
    # An older seqrun kept one zero per arm type and user: after the upgrade the arm must be
    # recorded again, and the refusal says why the old file does not count.
    old = tmp_path / "xdg" / "seqrun" / "zero-lwa3.json"
    old.parent.mkdir(parents=True)
    old.write_text(json.dumps({"arms": {"lwa3": {"record": {"pose": "park"}}}}))
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    monkeypatch.chdir(tmp_path)
    connection = hardware()
    try:
        with pytest.raises(UserInputError) as info:
            zero_at_run_start(connection, ARM, lambda q: True, print)
    finally:
        connection.close()
    message = str(info.value)
    assert message.startswith("no zero reference recorded for this arm")
    assert f"{old} is an older seqrun's record per arm type, not of this arm: it is not " \
           "used" in message


def test_an_older_campaign_record_above_the_current_folder_is_found(tmp_path):
    from seqrun.service.zero import older_records

    campaign = tmp_path / "campaign"
    (campaign / ".seqrun").mkdir(parents=True)
    (campaign / ".seqrun" / "zero.json").write_text("{}")
    (campaign / "sequences").mkdir()
    assert campaign / ".seqrun" / "zero.json" in older_records(campaign / "sequences")
    assert campaign / ".seqrun" / "zero.json" not in older_records(tmp_path)
