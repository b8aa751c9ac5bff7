"""The part between the simulated gripper's jaws is declared where the engineer sees it
(the grip step's part_width_mm, or the campaign's ``[sim] gripper_part_mm``) and the dry
run and every simulated run use the same one (seqrun/service/simulated_part.py)."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys

import can
import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands on the app)
from projecttree import CONFIG, make_project
from seqrun.cli.app import app
from seqrun.powercube.codec import GetParam, decode_ack, encode
from seqrun.powercube.protocol import ParamId

GRIP = """\
- include: startup.yaml
- release: {width_mm: 60}
- grip: {part_width_mm: 40, force_n: 100, window_mm: 2}
- check_gripper: {holding: true, width_mm: 40}
"""
NO_PART = ("grip: the jaws closed to 0.0 mm, past the part (40 ± 2 mm): no part between the "
           "jaws")


def _campaign(tmp_path, sim: str = ""):
    root = make_project(tmp_path / "c")
    (root / "seqrun.toml").write_text(CONFIG + sim, encoding="utf-8")
    path = root / "sequences" / "g.yaml"
    path.write_text("name: G\ndescription: grip\nsteps:\n" + GRIP, encoding="utf-8")
    return root, path


def _invoke(*args):
    result = CliRunner().invoke(app, [*map(str, args)])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    assert "Traceback" not in result.output
    return result


def _validate(path) -> tuple[int, dict]:
    result = _invoke("validate", "--json", path)
    return result.exit_code, json.loads(result.stdout)


def _run(path, folder, *extra) -> tuple[int, dict]:
    result = _invoke("run", path, "--virtual-time", "--yes", "--plain", "--no-report",
                     "--log-dir", folder, *extra)
    return result.exit_code, json.loads((folder / "report.json").read_text())


def test_the_campaign_rehearses_a_missing_part_in_the_dry_run_and_the_run(tmp_path):
    _, path = _campaign(tmp_path, "[sim]\ngripper_part_mm = 0\n")
    code, checked = _validate(path)
    assert code == 1 and checked["dry_run"]["message"] == NO_PART
    code, report = _run(path, tmp_path / "run")
    assert code == 3 and report["message"] == NO_PART
    record = json.loads((tmp_path / "run" / "record.json").read_text())
    assert "no part between the simulated jaws (seqrun.toml [sim] gripper_part_mm)" in \
        json.dumps(record)


def test_the_campaign_part_wins_over_the_steps(tmp_path):
    _, path = _campaign(tmp_path, "[sim]\ngripper_part_mm = 50\n")
    short = "grip: the jaws stopped at 50.0 mm, short of the part (40 ± 2 mm)"
    code, checked = _validate(path)
    assert code == 1 and checked["dry_run"]["message"] == short
    code, report = _run(path, tmp_path / "run")
    assert code == 3 and report["message"] == short


def test_the_steps_part_without_a_campaign_setting(tmp_path):
    _, path = _campaign(tmp_path)
    code, checked = _validate(path)
    assert code == 0, checked
    code, report = _run(path, tmp_path / "run")
    assert code == 0, report["message"]
    assert [s["width_mm"] for s in checked["dry_run"]["steps"] if s["kind"] == "grip"] == \
        [s["width_mm"] for s in report["steps"] if s["kind"] == "grip"]


def test_a_part_given_by_hand_still_wins_in_a_run(tmp_path):
    _, path = _campaign(tmp_path)
    code, report = _run(path, tmp_path / "run", "--bus-kwargs", "gripper_part_mm=0")
    assert code == 3 and report["message"] == NO_PART


@pytest.mark.parametrize("value, message", [
    ("true", "a width is a number of mm, got True"),
    ('"40"', "a width is a number of mm, got '40'"),
    ("-1", "greater than or equal to 0"),
])
def test_a_bad_campaign_part_is_one_line(tmp_path, value, message):
    _, path = _campaign(tmp_path, f"[sim]\ngripper_part_mm = {value}\n")
    result = _invoke("validate", path)
    assert result.exit_code == 2
    assert re.search(r"seqrun\.toml:5:\d+: ", result.output), result.output
    assert message in result.output


@pytest.mark.slow  # a subprocess serving in real time
def test_sim_serve_carries_the_campaigns_gripper_and_part(tmp_path):
    root, _ = _campaign(tmp_path, "[sim]\ngripper_part_mm = 40\n")
    process = subprocess.Popen(
        [sys.executable, "-m", "seqrun", "sim", "serve", "--port", "0", "--project", str(root)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        banner = "".join(iter(process.stdout.readline, "Ctrl-C to stop.\n"))
        assert "gripper: a 40 mm part between the simulated jaws (seqrun.toml [sim] " \
               "gripper_part_mm)" in banner, banner
        port = int(re.search(r"127\.0\.0\.1:(\d+)", banner).group(1))
        with can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0",
                     ignore_config=True) as bus:
            can_id, data = encode(GetParam(8, ParamId.CUBE_STATE))
            bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
            msg = bus.recv(5.0)
            assert msg is not None and msg.arbitration_id == 0x0A8  # the gripper answers
            assert decode_ack(msg.arbitration_id, bytes(msg.data)).module == 8
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=10)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
