"""Issue 43, "Wrong zero after a power cycle", through the command line against
`seqrun sim serve` (treated as real hardware). A power cycle is a restart of the server
with the same serial base; ``--home-ok-at-power-on`` makes its modules power on homed.

On the code before the fix: the record's old ``in_use`` (Park) was taken as the zero
because the modules were homed, `seqrun home` and the Op-safe run asked nothing and the
run PASSED with j4 at 190°; ``--zero-confirmed totem`` (the truth) was refused.
"""

from __future__ import annotations

import json

import pytest

from projecttree import ROOT
from runfolder import RunFolder
from test_zero_processes import Server, environment, flat, seqrun

pytestmark = pytest.mark.slow

#: One physical arm, powered on again and again (module M says SERIAL_BASE + M).
SERIAL_BASE = 7_430_000
OPSAFE = [70, 30, 0, 70, 20, 50, 0]


def bus(server: Server) -> list[str]:
    return ["-i", "socketcand", "--bus-kwargs", f"port={server.port}"]


def confirm_park_then_shut_down_at_totem(env: dict, *serve_args: str) -> None:
    """A power-on at Park, recorded and confirmed (the start-up: no motion), then the
    shutdown's record: Totem."""
    with Server(env, "--serial-base", str(SERIAL_BASE), *serve_args) as server:
        assert seqrun(env, "zero", "set", "park", "--yes", *bus(server)).returncode == 0
        started = seqrun(env, "run", ROOT / "sequences" / "startup.yaml", "--yes",
                         "--zero-confirmed", "park", "--plain", "--no-report", *bus(server))
        assert started.returncode == 0, started.stdout + started.stderr
        down = seqrun(env, "zero", "set", "totem", "--yes", *bus(server))
        assert down.returncode == 0, down.stdout + down.stderr


def test_power_cycled_homed_in_totem_asks_the_zero_and_reaches_opsafe(tmp_path, monkeypatch):
    env = environment(tmp_path / "state")
    env["SEQRUN_RESPONSE_TIMEOUT_MS"] = "200"  # (a loaded test machine)
    confirm_park_then_shut_down_at_totem(env)
    # Powered on again standing in Totem; the modules power on homed.
    with Server(env, "--serial-base", str(SERIAL_BASE), "--power-on-at", "totem",
                "--home-ok-at-power-on") as server:
        home = seqrun(env, "home", *bus(server))
        assert home.returncode == 130, home.stdout + home.stderr
        assert "Does the arm stand in Totem now" in flat(home.stdout)
        asked = seqrun(env, "run", ROOT / "sequences" / "opsafe.yaml", "--yes", "--plain",
                       "--log-dir", tmp_path / "asked", *bus(server))
        assert asked.returncode == 130, asked.stdout + asked.stderr
        assert "(confirmed at this power-on)" not in flat(asked.stdout)
        assert "Does the arm stand in Totem now" in flat(asked.stdout)
        assert RunFolder(tmp_path / "asked").trace_path() is None  # nothing sent
        wrong = seqrun(env, "run", ROOT / "sequences" / "opsafe.yaml", "--yes", "--plain",
                       "--zero-confirmed", "park", "--log-dir", tmp_path / "wrong",
                       *bus(server))
        assert wrong.returncode == 2, wrong.stdout + wrong.stderr
        for attempt in range(3):  # (a miss of the answer timeout on a loaded machine)
            done = seqrun(env, "run", ROOT / "sequences" / "opsafe.yaml", "--yes", "--plain",
                          "--zero-confirmed", "totem", "--no-report",
                          "--log-dir", tmp_path / f"done{attempt}", *bus(server))
            if not (done.returncode == 3 and "no acknowledge" in done.stdout):
                break
            assert seqrun(env, "reset", *bus(server)).returncode == 0
        assert done.returncode == 0, done.stdout + done.stderr
        status = seqrun(env, "status", "--json", *bus(server))
    assert status.returncode == 0, status.stdout + status.stderr
    joints = json.loads(status.stdout[status.stdout.index("{"):])["joints"]
    assert [j["position_deg"] for j in joints] == pytest.approx(OPSAFE, abs=0.25)


def test_modules_that_keep_the_value_make_every_command_ask(tmp_path):
    """The pessimistic firmware (it saves FHomeVel): no mark is believed, so even without
    a power cycle the next command asks the zero again."""
    env = environment(tmp_path / "state")
    option = ("--module-option", "fhome_vel_saved_on_write=true")
    with Server(env, "--serial-base", str(SERIAL_BASE + 100_000), *option) as server:
        assert seqrun(env, "zero", "set", "park", "--yes", *bus(server)).returncode == 0
        first = seqrun(env, "home", "--zero-confirmed", "park", *bus(server))
        assert first.returncode == 0, first.stdout + first.stderr
        assert "do not keep a power-session mark" in flat(first.stdout)
        again = seqrun(env, "home", *bus(server))
    assert again.returncode == 130, again.stdout + again.stderr
    assert "Does the arm stand in Park now" in flat(again.stdout)
