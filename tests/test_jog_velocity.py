"""Jog in velocity mode (the thesis GUI's FVEL jog), through the session as a face uses it.

The jog streams FVEL (not FRAMP), the modules' watchdog is armed before the first FVEL and
disarmed at the clean end, the deadman still ends it with a controlled stop, and a host that
goes silent mid-jog is stopped by the modules themselves.
"""

from __future__ import annotations

import pytest

from seqrun.clock import VirtualClock
from seqrun.errors import Refused
from seqrun.powercube.protocol import ConfigFlag, ParamId, StateFlag
from test_session import Frames, events_of, open_session

FVEL_ACK, FRAMP_ACK = 0x11, 0x0E


@pytest.fixture
def session(tmp_path):
    s = open_session(tmp_path)
    s.poll_status()
    assert s.arm_up().ok and s.home().ok
    s.poll_status()
    yield s
    s.close()


def modes(frames: Frames) -> set[int]:
    return {f[2][1] for f in frames.motion()}


def test_a_velocity_jog_goes_out_as_fvel_and_stops_under_the_deadman(session):
    frames = Frames(session)
    sub = session.subscribe(maxsize=100_000)
    start = session.status().joints_deg["j1"]
    result = session.jog("j1", 0.5, mode="velocity").wait(60)
    assert result.ok and "not renewed within 200 ms" in result.message
    assert FVEL_ACK in modes(frames) and FRAMP_ACK not in modes(frames)
    types = [e.type for e in events_of(sub)]
    assert "controlled_stop" in types and "fault" not in types
    assert types.index("watchdog_enabled") < types.index("setpoint")
    assert "watchdog_disabled" in types  # a clean end: the arm holds, no watchdog expiry
    moved = session.status().joints_deg["j1"] - start
    assert 0 < moved < 5
    assert all(v == 0.0 for v in session.status().velocities_deg_s.values())
    # disarmed: time passing without frames does not fault the modules
    session.clock.sleep(1.0)
    sim = session.connection.bus.arm
    assert not sim.module(1).state() & StateFlag.ERROR
    assert not int(sim.module(1).parameter(ParamId.CONFIG)) & ConfigFlag.WATCHDOG_ENABLE


def test_a_position_jog_still_sends_framp(session):
    frames = Frames(session)
    assert session.jog("j1", 0.5).wait(60).ok
    assert FRAMP_ACK in modes(frames) and FVEL_ACK not in modes(frames)


def test_an_unknown_jog_mode_is_refused_without_a_frame(session):
    frames = Frames(session)
    with pytest.raises(Refused, match="mode 'teleport'"):
        session.jog("j1", 0.5, mode="teleport")
    assert frames.motion() == []


def test_a_silent_host_mid_velocity_jog_is_stopped_by_the_watchdog(tmp_path):
    """The loop stops talking 0.3 s into the jog (no frame for 1 s): the module stops by
    itself within the watchdog timeout; the jog then ends in a fault with a Halt."""
    clock = VirtualClock()
    s = open_session(tmp_path, clock=clock)
    try:
        s.poll_status()
        assert s.arm_up().ok and s.home().ok
        s.poll_status()
        sub = s.subscribe(maxsize=100_000)
        stall: dict[str, float] = {}
        sim = s.connection.bus.arm

        def silent(slack: float) -> None:  # an idle hook of the jog's executor
            executor = s.activities.executor
            if executor is None or executor.last is None or stall:
                return
            if clock.now() - begun[0] > 0.3:
                stall["from"] = sim.module(1).position()
                stall["v"] = sim.module(1).velocity()
                clock.sleep(1.0)

        begun = [clock.now()]
        s.activities.add_idle_hook(silent)
        result = s.jog("j1", 0.5, mode="velocity").wait(60)
        assert stall and stall["v"] > 0
        assert not result.ok
        travelled = sim.module(1).position() - stall["from"]
        # stopped within the watchdog timeout (50 ms) plus half a refresh period
        assert 0 <= travelled <= stall["v"] * (0.05 + 0.03)
        assert sim.module(1).state() & StateFlag.COMM_ERROR
        types = [e.type for e in events_of(sub)]
        assert "fault" in types
    finally:
        s.close()
