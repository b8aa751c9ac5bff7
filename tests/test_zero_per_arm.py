"""The zero reference belongs to the physical arm (issue 23, "Wrong zero").

Each test reproduces one finding of the issue on the code before the fix:
- campaign B used its old Park zero after a power cycle at Totem, without asking;
- a second simulated arm (other serial numbers) was shown at the first arm's zero;
- an ``in_use`` edited by hand was used without a question;
- ``--yes`` answered "does the arm stand in Totem?".
And the recovery after a power loss mid-move: ``seqrun zero set --deg``.

"Real hardware" is a simulated arm behind a connection seqrun treats as real (in-process),
or served over socketcand in this process for the command line.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT, shipped_arm
from seqrun.cli.app import app
from seqrun.cli.zero import zero_at_run_start, zero_for_reading
from seqrun.clock import RealClock, VirtualClock
from seqrun.drivers.base import ArmIdentity
from seqrun.errors import UserInputError
from seqrun.results import EXIT_OK
from seqrun.sequence.loader import load_sequence
from seqrun.service.connection import Connection
from seqrun.service.runner import run_sequence
from seqrun.service.zero import ZeroStore
from seqrun.sim.arm import SimArm
from seqrun.sim.bus import SimBus
from seqrun.sim.module import ModuleOptions
from seqrun.sim.network import SimNetwork
from seqrun.sim.socketcand import SocketcandServer

ARM = shipped_arm()
FIRST = {m: 5_100_000 + m for m in range(1, 8)}
SECOND = {m: 6_200_000 + m for m in range(1, 8)}


@pytest.fixture(autouse=True)
def state_dir(tmp_path, monkeypatch):
    folder = tmp_path / "machine-state"
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(folder))
    return folder


def power_on(serials=FIRST) -> Connection:
    """The arm with ``serials`` freshly powered on (not homed; its modules read 0 where
    it stands), behind a connection treated as real hardware."""
    clock = VirtualClock()
    bus = SimBus(channel=f"arm-{id(clock)}", clock=clock, serials=serials)
    return Connection(bus, clock, False, "test bus (treated as real hardware)")


def store_of(serials=FIRST) -> ZeroStore:
    return ZeroStore(ArmIdentity.of(serials))


def run(connection, name: str, arm):
    loaded = load_sequence(ROOT / "sequences" / name)
    return run_sequence(loaded, arm, connection, log_dir=None, confirm=lambda q: True)


def module_deg(connection) -> np.ndarray:
    return np.degrees(list(connection.bus.arm.positions().values()))


@pytest.fixture
def served():
    """Serve an arm with given serials over socketcand in this process: ``serve(serials)``
    returns its ``-i socketcand`` options and the simulated arm."""
    servers = []

    def serve(serials, **arm_options):
        clock = RealClock()
        arm = SimArm(clock, serials=serials, **arm_options)
        server = SocketcandServer(SimNetwork(clock, arm, spin_window=0.0), port=0)
        server.start()
        servers.append(server)
        return ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1",
                f"port={server.port}"], arm
    yield serve
    for server in servers:
        server.shutdown()


def invoke(*args, stdin: str = ""):
    return CliRunner().invoke(app, [str(a) for a in args], input=stdin)


# --------------------------------------------------------------------------- campaigns
def test_campaign_b_after_a_power_cycle_at_totem_uses_the_arms_zero():
    """Two campaigns on one arm (a campaign is no input of the zero: the record is the
    arm's). Campaign B confirmed Park at an earlier power-on; the arm was shut down at Totem
    by campaign A and powered on again there, and A confirmed Totem and started the
    modules. Campaign B now uses Totem (the arm's zero), not its old Park: the move "to
    Totem" leaves the arm where it is."""
    store_of().set_record("park", by="test", joints_deg=ARM.power_off_joints_deg("park"))
    first = power_on()  # session 1, at Park
    try:
        zero_at_run_start(first, ARM, lambda q: True, print)
    finally:
        first.close()
    store_of().set_record("totem", by="shutdown.yaml",  # campaign A's shutdown
                          joints_deg=ARM.power_off_joints_deg("totem"))
    second = power_on()  # session 2, at Totem: the modules read 0 there
    questions = []
    try:
        zero_a = zero_at_run_start(second, ARM, lambda q: True, print)
        assert run(second, "startup.yaml", zero_a.apply(ARM)).result.exit_code == EXIT_OK
        zero_b = zero_at_run_start(second, ARM, lambda q: questions.append(q) or True,
                                   print)
        outcome = run(second, "totem.yaml", zero_b.apply(ARM))
        physical = module_deg(second)
    finally:
        second.close()
    assert zero_b.pose == "totem" and zero_b.source == "in_use" and questions == []
    assert outcome.result.exit_code == EXIT_OK
    # Totem is where the modules read 0; the old Park zero drove j2 to 90°, j4 to 120.32°.
    assert physical == pytest.approx([0.0] * 7, abs=0.05)


# --------------------------------------------------------------------------- two arms
def test_a_second_arm_is_not_shown_at_the_first_arms_zero(served):
    """Arm 1 was recorded at Totem. Arm 2 (other serials), powered on at Park, has no
    record: status says its zero is unknown and shows the arm file's Park offsets, and a
    run on it refuses before anything moves."""
    store_of(FIRST).set_record("totem", by="shutdown.yaml",
                               joints_deg=ARM.power_off_joints_deg("totem"))
    bus, _ = served(SECOND)
    status = invoke("status", "--json", *bus)
    assert status.exit_code == 0, status.output
    reading = json.loads(status.output[status.output.index("{"):])
    joints = {j["joint"]: j["position_deg"] for j in reading["joints"]}
    assert joints["j2"] == pytest.approx(-90.0) and joints["j4"] == pytest.approx(-120.32)
    connection = power_on(SECOND)
    try:
        arm, text = zero_for_reading(connection, ARM)
        with pytest.raises(UserInputError) as refused:
            zero_at_run_start(connection, ARM, lambda q: True, print)
    finally:
        connection.close()
    assert text.startswith("zero: unknown (no zero reference recorded for this arm "
                           "(serials 1:6200001")
    assert "nothing will move" in str(refused.value)


def test_a_module_exchanged_is_named(served):
    """One module of the recorded arm replaced: no record for this set of modules, and
    the refusal says which record shares the others."""
    store_of(FIRST).set_record("totem", by="shutdown.yaml",
                               joints_deg=ARM.power_off_joints_deg("totem"))
    connection = power_on({**FIRST, 4: 9_999_004})
    try:
        with pytest.raises(UserInputError) as refused:
            zero_at_run_start(connection, ARM, lambda q: True, print)
    finally:
        connection.close()
    assert "holds the record of an arm with module(s) 1, 2, 3, 5, 6, 7" in str(refused.value)


def test_a_file_of_other_serials_is_refused():
    """A record copied over this arm's file: one line naming both sets of serials."""
    store_of(SECOND).set_record("totem", by="test", joints_deg=ARM.power_off_joints_deg("totem"))
    mine = store_of(FIRST)
    mine.folder.mkdir(parents=True, exist_ok=True)
    mine.path.write_bytes(store_of(SECOND).path.read_bytes())
    connection = power_on(FIRST)
    try:
        with pytest.raises(UserInputError) as refused:
            zero_at_run_start(connection, ARM, lambda q: True, print)
    finally:
        connection.close()
    text = str(refused.value)
    assert "belongs to the arm with serials 1:6200001" in text
    assert "not to the connected modules (serials 1:5100001" in text and "\n" not in text


# --------------------------------------------------------------------------- hand edits
def _edit(store: ZeroStore, **changes) -> None:
    data = json.loads(store.path.read_text())
    for key, value in changes.items():
        data[key].update(value)
    store.path.write_text(json.dumps(data, indent=2))


def test_an_in_use_edited_by_hand_is_refused_not_used(served):
    """The arm was confirmed at Park and started; someone changes in_use to Totem in the
    file. seqrun refuses the file (one line, how to record again) instead of using it."""
    store = store_of()
    store.set_in_use(store.set_record("park", by="test",
                                      joints_deg=ARM.power_off_joints_deg("park")), 7)
    _edit(store, in_use={"pose": "totem"})
    # (the modules were started at this power-on: they report HOME_OK)
    bus, arm = served(FIRST, options=ModuleOptions(home_ok_at_power_on=True))
    result = invoke("run", ROOT / "sequences" / "totem.yaml", "--yes", "--plain",
                    "--no-report", *bus)
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "was changed outside seqrun" in errors[0]
    assert "record where the arm was powered off again with 'seqrun zero set POSE'" in errors[0]
    assert "Traceback" not in result.output
    assert list(arm.positions().values()) == [0.0] * 7


# --------------------------------------------------------------------------- --yes
def test_yes_does_not_answer_does_the_arm_stand_in_totem(served, tmp_path, monkeypatch):
    """With --yes and nobody at the keyboard the zero question is still asked, and
    unanswered it is a no: nothing moves. --zero-confirmed names the pose; a different
    pose than the record refuses."""
    # (a real-time arm in this process on a loaded test machine: 200 ms per answer)
    monkeypatch.setenv("SEQRUN_RESPONSE_TIMEOUT_MS", "200")
    bus, arm = served(FIRST)
    store_of().set_record("totem", by="shutdown.yaml", joints_deg=ARM.power_off_joints_deg("totem"))
    sequence = ROOT / "sequences" / "totem.yaml"
    declined = invoke("run", sequence, "--yes", "--plain", "--no-report", *bus)
    assert declined.exit_code == 130, declined.output
    flat = " ".join(declined.output.split())
    assert "Does the arm stand in Totem now" in flat and "yes (--yes)" not in flat.split(
        "Does the arm stand in Totem now")[1]
    assert "--yes does not answer the zero question" in flat and "Not started" in flat
    wrong = invoke("run", sequence, "--yes", "--zero-confirmed", "park", "--plain",
                   "--no-report", *bus)
    assert wrong.exit_code == 2, wrong.output
    assert "error: --zero-confirmed park: the zero reference in force is Totem" in \
        " ".join(wrong.output.split())
    assert store_of().in_use is None
    assert list(arm.positions().values()) == [0.0] * 7
    confirmed = invoke("run", sequence, "--yes", "--zero-confirmed", "totem", "--plain",
                       "--no-report", "--log-dir", tmp_path / "run", *bus)
    assert confirmed.exit_code == 0, confirmed.output
    assert "Totem now (j1 0°, j2 0°, j3 0°, j4 0°, j5 0°, j6 0°, j7 0°)? yes " \
        "(--zero-confirmed totem)" in " ".join(confirmed.output.split())
    assert store_of().in_use.record.pose == "totem"


def test_zero_set_on_the_built_in_simulator_is_one_line():
    """The built-in simulator's zero is its power-on pose: there is no arm to record."""
    result = invoke("zero", "set", "totem", "--yes")
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: no arm named: the built-in "
                                                   "simulator takes its zero from")


# --------------------------------------------------------------------------- power loss
def test_zero_set_deg_records_a_power_loss_pose_and_the_run_uses_it(served):
    """Power lost mid-move at Q: the modules read 0 there at the next power-on. Recorded
    with --deg Q and confirmed, a move to Op-safe puts every module at opsafe - Q."""
    lost_at = [12.5, -35.0, 0.0, 80.0, 0.0, 40.0, -7.25]
    bus, _ = served(FIRST)
    short = invoke("zero", "set", "--deg", "1", "2", "--yes", *bus)
    assert short.exit_code == 2 and "--deg: the arm has 7 joints" in short.output
    both = invoke("zero", "set", "totem", "--deg", *lost_at, "--yes", *bus)
    assert both.exit_code == 2 and "one of them" in both.output
    done = invoke("zero", "set", "--deg", *lost_at, "--yes", *bus)
    assert done.exit_code == 0, done.output
    assert "was powered off in the pose (j1 12.5°, j2 -35°" in " ".join(done.output.split())
    connection = power_on()
    questions = []
    try:
        zero = zero_at_run_start(connection, ARM,
                                 lambda q: questions.append(q) or True, print)
        outcome = run(connection, "opsafe.yaml", zero.apply(ARM))
        physical = module_deg(connection)
    finally:
        connection.close()
    assert "stand in the pose j1 12.5°, j2 -35°" in questions[0]
    assert outcome.result.exit_code == EXIT_OK
    opsafe = [70, 30, 0, 70, 20, 50, 0]
    expected = [q - lost for q, lost in zip(opsafe, lost_at)]
    assert physical == pytest.approx(expected, abs=0.25)
    assert not math.isclose(physical[0], opsafe[0], abs_tol=1.0)


# --------------------------------------------------------------------------- simulator
def test_every_simulated_arm_has_serials_of_its_own_unless_named():
    """Two simulated arms are two arms (their serials differ); serial_base names them, for
    the built-in simulator too (--bus-kwargs / SEQRUN_SIM_OPTIONS)."""
    from seqrun.service.connection import open_connection

    clock = VirtualClock()
    first, second = SimArm(clock).serials, SimArm(clock).serials
    assert first != second and len(set(first.values())) == 7
    named = SimArm(clock, options=ModuleOptions(serial_base=7_000_000)).serials
    assert named == {m: 7_000_000 + m for m in range(1, 8)}
    connection = open_connection(force_sim=True, clock=VirtualClock(),
                                 bus_kwargs={"serial_base": "4400"})
    try:
        assert connection.bus.arm.serials[3] == 4403
    finally:
        connection.close()
    with pytest.raises(ValueError, match="serials are 32-bit"):
        SimArm(clock, options=ModuleOptions(serial_base=2**32 - 3))


def test_zero_set_while_the_modules_are_on_says_the_zero_in_use_stays(served):
    """A record made while the modules are on (they hold the mark of the zero confirmed
    at this power-on) is the next power-on's zero: the runs until then keep the one
    confirmed at this power-on, and zero set says so."""
    store = store_of()
    store.set_record("park", by="test", joints_deg=ARM.power_off_joints_deg("park"))
    bus, _ = served(FIRST, options=ModuleOptions(home_ok_at_power_on=True))
    confirmed = invoke("home", "--zero-confirmed", "park", *bus)
    assert confirmed.exit_code == 0, confirmed.output
    result = invoke("zero", "set", "totem", "--yes", *bus)
    assert result.exit_code == 0, result.output
    assert "note: the modules are still on: runs keep the zero confirmed at this " \
        "power-on (Park, recorded" in " ".join(result.output.split())
    assert store.record.pose == "totem" and store.in_use.record.pose == "park"


def test_zero_confirmed_must_name_the_zero_in_force_on_the_simulator_too():
    """--zero-confirmed is a statement about the arm: the simulator powered on at Park
    refuses 'totem' (nothing sent) and takes 'park'."""
    from seqrun.service.connection import open_connection

    connection = open_connection(force_sim=True, clock=VirtualClock(), power_on_pose="park")
    try:
        with pytest.raises(UserInputError, match="--zero-confirmed totem: the zero "
                                                 "reference in force is Park"):
            zero_at_run_start(connection, ARM, lambda q: True, print, confirmed="totem")
        zero = zero_at_run_start(connection, ARM, lambda q: False, print,
                                 confirmed="Park")
    finally:
        connection.close()
    assert zero.pose == "park" and zero.question is None


def test_a_power_off_step_that_cannot_write_the_record_fails_the_run(tmp_path, monkeypatch):
    """The shutdown's record cannot be written (a machine folder this user may not write):
    the power_off step fails with one line saying the zero is not recorded."""
    from seqrun.errors import RunAborted
    from seqrun.service import campaign_records

    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")  # the store's folder cannot be made under a file
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(blocked))
    loaded = load_sequence(ROOT / "sequences" / "shutdown.yaml")
    record = campaign_records.zero_recorder(store_of(), ARM, loaded)
    with pytest.raises(RunAborted) as failed:
        record("totem")
    assert failed.value.cause == "power_off"
    assert "cannot write the zero reference" in str(failed.value)
    assert "NOT recorded" in str(failed.value) and "\n" not in str(failed.value)


def test_zero_confirmed_per_arm_reads_bare_and_named_poses():
    from seqrun.service.zero import confirmed_per_arm

    assert confirmed_per_arm([], ["A", "B"]) == {}
    assert confirmed_per_arm(["park"], ["A", "B"]) == {"A": "park", "B": "park"}
    assert confirmed_per_arm(["B=totem"], ["A", "B"]) == {"B": "totem"}
    assert confirmed_per_arm(["park", "B=totem"], ["A", "B"]) == {"A": "park", "B": "totem"}
    assert confirmed_per_arm(["totem"], [None]) == {None: "totem"}
    assert confirmed_per_arm(["A=totem"], ["A"]) == {"A": "totem"}
    with pytest.raises(UserInputError, match="this arm has no id"):
        confirmed_per_arm(["A=totem"], [None])
    with pytest.raises(UserInputError, match="name the pose the arm stands in"):
        confirmed_per_arm([""], ["A", "B"])
