"""A run uses exactly the inputs that were validated (issue 16, item 2): pose files are
read once, when the sequence is loaded, and the run folder records every input's sha256."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from projecttree import make_project
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.results import EXIT_OK
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.drivers.powercube.units import to_user_deg


#: Op-safe rewritten to a pose below the desk (what the red team wrote mid-run).
BELOW_THE_DESK = {"j1": 70.0, "j2": 100.0, "j3": 0.0, "j4": 100.0, "j5": 20.0, "j6": 50.0,
                  "j7": 0.0}


@pytest.fixture
def project(tmp_path: Path) -> Path:
    return make_project(tmp_path / "project", sequences="*")


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_pose_file_rewritten_mid_run_changes_nothing(project, tmp_path):
    opsafe = project / "poses" / "opsafe.yaml"
    validated_sha = _sha(opsafe)
    loaded = load_sequence(project / "sequences" / "opsafe.yaml")
    arm = load_arm(loaded.arm_path)
    rewritten = []

    def rewrite_after_the_move_to_totem(event: dict) -> None:
        # step 5 is "Up to Totem"; step 6 moves to Op-safe
        if event["type"] == "step_finished" and event.get("step") == 5:
            text = opsafe.read_text()
            for name, value in BELOW_THE_DESK.items():
                text = text.replace(f"  {name}: {loaded.poses['opsafe'].joints_deg[name]}",
                                    f"  {name}: {value}")
            opsafe.write_text(text)
            rewritten.append(_sha(opsafe))

    connection = open_connection(force_sim=True, clock=VirtualClock())
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               confirm=lambda prompt: True,
                               listeners=[rewrite_after_the_move_to_totem],
                               html_report=False)
        at = connection.bus.arm.positions()
    finally:
        connection.close()
    assert rewritten and rewritten[0] != validated_sha  # the file did change mid-run
    assert outcome.result.exit_code == EXIT_OK, outcome.result.message
    reached = {j.name: to_user_deg(j, at[j.module]) for j in arm.joints}
    validated = loaded.poses["opsafe"].joints_deg
    assert all(abs(reached[n] - validated[n]) < 0.2 for n in validated), reached
    report = RunFolder(tmp_path / "run").report()
    recorded = {Path(i["file"]).name: i for i in report["inputs"]}
    assert recorded["opsafe.yaml"]["sha256"] == validated_sha
    assert recorded["opsafe.yaml"]["kind"] == "pose"
    assert recorded["startup.yaml"]["sha256"] == _sha(project / "sequences" / "startup.yaml")
    assert recorded["lwa3.yaml"]["kind"] == "arm"
    assert recorded["lwa3.yaml"]["sha256"] == _sha(project / "arms" / "lwa3.yaml")


def test_poses_are_read_once_with_the_sequence(project):
    loaded = load_sequence(project / "sequences" / "opsafe.yaml")
    (project / "poses" / "opsafe.yaml").unlink()
    (project / "poses" / "totem.yaml").unlink()
    assert loaded.poses["opsafe"].joints_deg["j1"] == 70.0
    assert set(loaded.poses) == {"totem", "opsafe"}
