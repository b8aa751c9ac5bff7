"""The arm's identity, checked before every motion (issue 43, "Wrong zero after a power
cycle").

The modules take their zero where they were powered off. seqrun took "every module
reports HOME_OK" as "not power-cycled", so modules that power on homed (or an arm homed by
``seqrun home``) kept an earlier power-on's zero; the record kept a pose *name*; ``pose
save`` wrote angles against an assumed zero; ``zero set --deg`` recorded any number.

Here on the in-process simulator at virtual time (a power cycle: a new simulated bus with
the same serial numbers, whose modules start from their stored parameters); the issue's
own scenario through the command line against ``seqrun sim serve`` is in
``test_arm_identity_cli.py``.
"""

from __future__ import annotations

import hashlib
import json

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ARM_FILE, shipped_arm
from seqrun.arm.description import load_arm
from seqrun.cli.app import app
from seqrun.clock import VirtualClock
from seqrun.drivers.base import ArmIdentity
from seqrun.drivers.registry import open_driver
from seqrun.errors import UserInputError
from seqrun.service.arm_identity import IdentityRefused, check_identity
from seqrun.service.connection import Connection
from seqrun.service.zero import (OLD_FORMAT, ZeroStore, zero_at_start, zero_for_run)
from seqrun.sim.bus import SimBus
from seqrun.sim.module import ModuleOptions

ARM = shipped_arm()
SERIALS = {m: 4_300_000 + m for m in range(1, 8)}


@pytest.fixture(autouse=True)
def state_dir(tmp_path, monkeypatch):
    folder = tmp_path / "state"
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(folder))
    return folder


def power_on(serials=SERIALS, **options) -> Connection:
    """The arm with ``serials`` freshly powered on where it stands (its modules read 0
    there), behind a connection treated as real hardware."""
    clock = VirtualClock()
    bus = SimBus(channel=f"arm-{id(clock)}", clock=clock, serials=serials,
                 options=ModuleOptions(**options))
    return Connection(bus, clock, False, "test bus (treated as real hardware)")


def store_of(serials=SERIALS) -> ZeroStore:
    return ZeroStore(ArmIdentity.of(serials))


def record(pose: str, by: str = "test") -> None:
    store_of().set_record(pose, by=by, joints_deg=ARM.power_off_joints_deg(pose))


def decide(connection, answer: bool = True, confirmed: str | None = None):
    """The zero decision of a command's start: ``(zero, questions asked)``."""
    questions: list[str] = []
    zero = zero_at_start(connection, ARM, ask=lambda q: questions.append(q) or answer,
                         show=lambda text: None, confirmed=confirmed)
    return zero, questions


# --------------------------------------------------------------------------- the RAM mark
def test_the_mark_lives_in_the_modules_until_they_power_off():
    connection = power_on()
    driver = open_driver(ARM, connection)
    try:
        assert driver.session_mark() is None  # nothing written since power-on
        assert driver.write_session_mark(1234) is True
        assert driver.session_mark() == 1234
    finally:
        driver.close()
        connection.close()
    again = power_on()  # the same modules, powered off and on: their RAM is gone
    driver = open_driver(ARM, again)
    try:
        assert driver.identity() == ArmIdentity.of(SERIALS)
        assert driver.session_mark() is None
    finally:
        driver.close()
        again.close()


def test_the_mark_is_a_tiny_change_of_the_homing_velocity_and_reads_back():
    from seqrun.drivers.powercube.session_mark import mark_of, marked_velocity

    for stored in (0.1, -0.25, 1.0):
        for mark in (1, 777, 4095):
            velocity = marked_velocity(stored, mark)
            assert velocity != stored and abs(velocity - stored) <= 5e-4 * abs(stored)
            assert mark_of(velocity, stored) == mark
        assert mark_of(stored, stored) is None        # a power-on: the stored value
        assert mark_of(stored * 1.5, stored) is None  # somebody set another velocity
    with pytest.raises(ValueError):
        marked_velocity(0.1, 4096)


def test_a_firmware_that_saves_the_value_reads_as_no_mark():
    """The pessimistic firmware (FHomeVel saved as the stored DefHomeVel): a mark that
    would outlive a power cycle is never believed."""
    connection = power_on(fhome_vel_saved_on_write=True)
    driver = open_driver(ARM, connection)
    try:
        assert driver.write_session_mark(99) is False
        assert driver.session_mark() is None
    finally:
        driver.close()
        connection.close()


# --------------------------------------------------------------------------- power cycles
def test_modules_that_power_on_homed_are_still_seen_power_cycled():
    """The issue: confirmed at Park, shut down at Totem, powered on (homed) in Totem. The
    old in_use (Park) is not used, it is cleared, and Totem is asked about."""
    record("park")
    first = power_on()
    try:
        zero, questions = decide(first)
    finally:
        first.close()
    assert zero.pose == "park" and questions and zero.session_mark is not None
    record("totem", by="shutdown.yaml")
    second = power_on(home_ok_at_power_on=True)
    try:
        assert open_driver(ARM, second).homed()  # (what the old check trusted)
        zero, questions = decide(second)
    finally:
        second.close()
    assert zero.pose == "totem" and zero.source == "record"
    assert questions and "stand in Totem now (j1 0°, j2 0°" in questions[0]
    assert store_of().in_use.record.pose == "totem"


def test_the_stale_in_use_is_cleared_even_when_the_operator_says_no():
    record("park")
    first = power_on()
    try:
        decide(first)
    finally:
        first.close()
    record("totem", by="shutdown.yaml")
    second = power_on(home_ok_at_power_on=True)
    try:
        with pytest.raises(UserInputError, match="Not started"):
            decide(second, answer=False)
    finally:
        second.close()
    assert store_of().in_use is None and not store_of().holds_in_use()


def test_while_the_modules_stay_on_the_next_command_asks_nothing():
    record("park")
    connection = power_on()
    try:
        first, asked_first = decide(connection)
        second, asked_second = decide(connection)
    finally:
        connection.close()
    assert asked_first and asked_second == []
    assert second.source == "in_use" and second.session_mark == first.session_mark


def test_without_a_mark_every_command_asks_again():
    """Modules that keep no mark (the firmware saved it): safe, the zero is asked at every
    command."""
    record("park")
    connection = power_on(fhome_vel_saved_on_write=True)
    try:
        first, asked_first = decide(connection)
        second, asked_second = decide(connection)
    finally:
        connection.close()
    assert asked_first and asked_second
    assert first.session_mark is None and second.source == "record"


# --------------------------------------------------------------------------- the gate
def test_check_identity_refuses_power_cycled_or_other_modules():
    record("park")
    connection = power_on()
    try:
        zero, _ = decide(connection)
        driver = open_driver(zero.apply(ARM), connection)
        check_identity(driver, zero)  # the same power session: passes
        driver.close()
    finally:
        connection.close()
    cycled = power_on(home_ok_at_power_on=True)
    other = power_on({m: 9_100_000 + m for m in range(1, 8)})
    try:
        with pytest.raises(IdentityRefused, match="powered off since their zero was "
                                                  "confirmed") as info:
            check_identity(open_driver(ARM, cycled), zero)
        assert "\n" not in str(info.value)
        with pytest.raises(IdentityRefused, match="are not the arm whose zero is in force"):
            check_identity(open_driver(ARM, other), zero)
    finally:
        cycled.close()
        other.close()


def test_a_session_refuses_a_move_after_a_power_cycle_and_sends_nothing():
    """The console, Foxglove, ROS and jog move through an ArmSession: the session checks
    the arm's identity as a motion starts. Its zero was confirmed on modules that were
    then power-cycled (homed at power-on): the move is refused, nothing is sent."""
    from seqrun.service.session import ArmSession

    record("park")
    before = power_on()
    try:
        zero, _ = decide(before)
    finally:
        before.close()
    cycled = power_on(home_ok_at_power_on=True)
    sent: list = []
    session = ArmSession(zero.apply(ARM), cycled, zero=zero, status_hz=0)
    try:
        session.poll_status()
        session.driver.add_frame_listener(sent.append)
        with pytest.raises(IdentityRefused, match="powered off since"):
            session.move_to_pose("opsafe")
        assert session.activity is None
    finally:
        session.close()
    motion = [f for f in sent if not f.is_rx and f.data[:1] == b"\x0b"]
    assert motion == []


# --------------------------------------------------------------------------- the record
def test_the_record_keeps_the_angles_and_an_arm_file_with_other_angles_is_refused(tmp_path):
    """The record says where Totem was; an arm file whose "totem" stands 10° elsewhere in
    j2 neither runs with its own angles nor silently with the record's."""
    record("totem")
    data = json.loads(store_of().path.read_text())
    assert data["record"]["joints_deg"] == ARM.power_off_joints_deg("totem")
    text = ARM_FILE.read_text().replace(
        "offsets_deg: {j1: 0.0, j2: 0.0, j3: 0.0, j4: 0.0, j5: 0.0, j6: 0.0, j7: 0.0}",
        "offsets_deg: {j1: 0.0, j2: -10.0, j3: 0.0, j4: 0.0, j5: 0.0, j6: 0.0, j7: 0.0}")
    other = tmp_path / "lwa3.yaml"
    other.write_text(text)
    moved_totem = load_arm(other)
    assert moved_totem.power_off_joints_deg("totem")["j2"] == 10.0
    connection = power_on()
    try:
        with pytest.raises(UserInputError, match="the arm file and the record disagree") as info:
            zero_at_start(connection, moved_totem, ask=lambda q: True, show=lambda t: None)
    finally:
        connection.close()
    assert "\n" not in str(info.value) and store_of().in_use is None


def test_zero_confirmed_compares_angles_not_names(tmp_path):
    """--zero-confirmed answers the question only with the recorded pose's angles."""
    record("totem")
    connection = power_on()
    try:
        with pytest.raises(UserInputError, match="--zero-confirmed park: the zero "
                                                 "reference in force is Totem"):
            decide(connection, confirmed="park")
        zero, _ = decide(connection, confirmed="TOTEM")
    finally:
        connection.close()
    assert zero.pose == "totem" and zero.session_mark is not None


def _old_file(store: ZeroStore, **fields) -> None:
    """A file as seqrun's format 2 wrote it (a pose name only; its checksum)."""
    data = {"format": OLD_FORMAT, "arm": {"serials": {str(m): str(s)
                                                     for m, s in SERIALS.items()}},
            **fields}
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    data["checksum"] = "sha256:" + hashlib.sha256(text.encode("ascii")).hexdigest()
    store.folder.mkdir(parents=True, exist_ok=True)
    store.path.write_text(json.dumps(data, indent=2))


def test_an_older_record_by_name_is_asked_about_again_then_written_with_its_angles():
    """Migration: a format-2 record names Totem and its in_use names Park. Neither has
    angles nor a mark, so the in_use is not used (the modules may have been power-cycled)
    and the record is asked about, with this arm file's angles said; once confirmed it is
    written with them."""
    store = store_of()
    old = {"pose": "totem", "recorded_at": "2026-11-20T17:03:00+01:00", "by": "shutdown.yaml",
           "user": "op"}
    _old_file(store, record=old, in_use={**old, "pose": "park"})
    assert store.record.by_name_only and store.in_use is None
    zero = zero_for_run(ARM, store, simulator_pose=None, session_mark=None)
    assert zero.source == "record" and "recorded by an older seqrun" in zero.question
    connection = power_on(home_ok_at_power_on=True)
    try:
        zero, questions = decide(connection)
    finally:
        connection.close()
    assert zero.pose == "totem" and questions
    data = json.loads(store.path.read_text())
    assert data["format"] == "seqrun zero reference 3"
    assert data["record"]["joints_deg"] == ARM.power_off_joints_deg("totem")
    assert data["in_use"]["session_mark"] == zero.session_mark


# --------------------------------------------------------------------------- commands
def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], input="")


@pytest.fixture
def served():
    """The tests' arm served over socketcand in this process: its ``-i socketcand``
    options."""
    from seqrun.clock import RealClock
    from seqrun.sim.arm import SimArm
    from seqrun.sim.network import SimNetwork
    from seqrun.sim.socketcand import SocketcandServer

    clock = RealClock()
    arm = SimArm(clock, serials=SERIALS)
    with SocketcandServer(SimNetwork(clock, arm, spin_window=0.0), port=0) as server:
        server.start()
        yield ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={server.port}"]


@pytest.mark.parametrize("angles", [["1e308", "0", "0", "0", "0", "0", "0"],
                                    ["0", "0", "0", "150", "0", "0", "0"],
                                    ["0", "0", "0", "0", "0", "0", "-1e400"]])
def test_zero_set_deg_accepts_only_finite_angles_within_the_limits(served, angles):
    result = invoke("zero", "set", "--deg", *angles, "--yes", *served)
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith("error: --deg: ")
    assert not store_of().path.exists()


def test_pose_save_without_a_confirmed_zero_is_refused(served, tmp_path):
    out = tmp_path / "here.yaml"
    none = invoke("pose", "save", "here", "-o", out, *served)
    assert none.exit_code == 2, none.output
    assert "no zero reference recorded" in none.output and not out.exists()
    record("park")
    unconfirmed = invoke("pose", "save", "here", "-o", out, *served)
    assert unconfirmed.exit_code == 2, unconfirmed.output
    errors = [line for line in unconfirmed.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "is not confirmed at this power-on: nothing saved" in errors[0]
    assert not out.exists()
    assert invoke("home", "--zero-confirmed", "park", *served).exit_code == 0
    saved = invoke("pose", "save", "here", "-o", out, *served)
    assert saved.exit_code == 0, saved.output
    assert out.exists()
