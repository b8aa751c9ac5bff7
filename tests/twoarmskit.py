"""Shared by the two-arm run tests: the example campaign of two arms (each on its built-in
simulator) copied into a test's folder, with a short sequence in which B waits for A."""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from projecttree import ROOT

EXAMPLE = ROOT / "examples" / "two-arms"

#: A moves and signals; B waits for it, then moves; both turn back together.
SHORT = """\
name: Short
description: Both arms turn, B after A has.
steps:
  - parallel:
      - arm: A
        steps: [include: startup.yaml, {move: {joints: {j1: 10}}}, signal: A_turned]
      - arm: B
        steps: [include: startup.yaml, wait_for: A_turned, {move: {joints: {j1: -10}}}]
  - parallel:
      - {arm: A, steps: [{move: {joints: {j1: 0}}}]}
      - {arm: B, steps: [{move: {joints: {j1: 0}}}]}
"""


def quiet(folder: Path, mp: pytest.MonkeyPatch) -> Path:
    """No CAN bus from the environment; HOME and the arms' state (zero records) inside
    ``folder``."""
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        mp.delenv(name, raising=False)
    mp.setenv("HOME", str(folder))
    mp.setenv("SEQRUN_STATE_DIR", str(folder / "state"))
    return folder


def two_arm_campaign(folder: Path, mp: pytest.MonkeyPatch, ros: str = "") -> Path:
    """``folder/two-arms``: the example campaign with ``sequences/short.yaml`` (and ``ros``
    appended to its seqrun.toml), made the working folder, the environment :func:`quiet`."""
    quiet(folder, mp)
    campaign = folder / "two-arms"
    shutil.copytree(EXAMPLE, campaign)
    (campaign / "sequences" / "short.yaml").write_text(SHORT)
    if ros:
        with (campaign / "seqrun.toml").open("a") as f:
            f.write(ros)
    mp.chdir(campaign)
    return campaign


# -- two served arms: each a simulated arm behind a socketcand server of its own --------
def served(serial_base: int, power_on_pose: str):
    """A simulated arm (serials ``serial_base + module id``, powered on at
    ``power_on_pose``) served over socketcand on a free port; ``shutdown()`` ends it."""
    from seqrun.clock import RealClock
    from seqrun.sim.arm import SimArm
    from seqrun.sim.network import SimNetwork
    from seqrun.sim.socketcand import SocketcandServer

    clock = RealClock()
    serials = {m: serial_base + m for m in range(1, 8)}
    server = SocketcandServer(SimNetwork(clock, SimArm(clock, power_on_pose=power_on_pose,
                                                       serials=serials),
                                         spin_window=0.0), port=0)
    server.start()
    return server


def two_served() -> tuple:
    """Arm A powered on at Park, arm B at Totem, each with serials of its own."""
    return served(5_100_000, "park"), served(5_200_000, "totem")


def served_campaign(first, second) -> str:
    """seqrun.toml of arms A and B on the two servers (B 900 mm away, turned 180°)."""
    return f"""\
[arms.A]
bus = {{ interface = "socketcand", channel = "can0", kwargs = {{ host = "127.0.0.1", port = {first.port} }} }}

[arms.B]
bus = {{ interface = "socketcand", channel = "can0", kwargs = {{ host = "127.0.0.1", port = {second.port} }} }}
base = {{ position_mm = [0, 900, 0], rpy_deg = [0, 0, 180] }}
"""


@contextlib.contextmanager
def two_served_campaign(folder: Path, mp: pytest.MonkeyPatch) -> Iterator[dict]:
    """:func:`two_served` arms named by ``folder/dual/seqrun.toml`` (the working folder,
    the environment :func:`quiet`): ``{"A": server, "B": server}``, shut down after."""
    quiet(folder, mp)
    first, second = two_served()
    try:
        campaign = folder / "dual"
        campaign.mkdir()
        (campaign / "seqrun.toml").write_text(served_campaign(first, second))
        mp.chdir(campaign)
        yield {"A": first, "B": second}
    finally:
        first.shutdown()
        second.shutdown()


def halted(server) -> bool:
    """Every module of the served arm reads HALTED."""
    from seqrun.powercube.protocol import StateFlag

    return all(StateFlag(s) & StateFlag.HALTED for s in server.network.arm.states().values())


def copy_example(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of the example campaign (arms A and B facing each other, 900 mm apart) as the
    working folder, with no CAN configuration and a state folder of the test's own."""
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    folder = tmp_path / "two-arms"
    shutil.copytree(EXAMPLE, folder)
    monkeypatch.chdir(folder)
    return folder


def write(folder: Path, name: str, text: str) -> Path:
    """``folder/sequences/name`` holding ``text``."""
    path = folder / "sequences" / name
    path.write_text(text)
    return path


def check(path: Path, **options):
    """The campaign check of a sequence of several arms (``dry_run=False``: static only)."""
    from seqrun.service.arms_check import campaign_has_arms, check_arms_sequence

    return check_arms_sequence(path, campaign_has_arms(path), **options)
