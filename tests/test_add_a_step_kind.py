"""Adding a step kind is one module and its line in the registry (issue 25).

A copy of the package gets ``seqrun/steps/fvel.py`` (a joint turned at a velocity for a
time) and the two lines of ``seqrun/steps/registry.py`` that import and list it, nothing
else; a process that imports the copy then reads, checks, describes, documents and runs
the new step like any other: the sequence file's union and JSON Schema, the loader, the
static checks at ``file:line:col``, the executor on the simulator (``seqrun validate``).
"""

from __future__ import annotations

import difflib
import json
import os
import shutil
import subprocess
import sys

from projecttree import ROOT

FVEL = '''\
"""fvel: turn one joint at a constant velocity for a time."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from pydantic import Field

from seqrun.steps.kind import StepKind
from seqrun.steps.params import Finite, JointName, Positive, StepParams, one_key_value

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class FvelParams(StepParams):
    """Turn one joint at a constant velocity for a time."""

    kind: ClassVar[str] = "fvel"
    yaml_name: ClassVar[str] = "fvel"

    joint: JointName = Field(description="The joint that turns.")
    velocity_deg_s: Finite = Field(description="Its velocity, deg/s (the sign: the way).")
    seconds: Positive = Field(description="For how long, seconds.")


def describe(params: FvelParams) -> str:
    return f"turn {params.joint} at {params.velocity_deg_s:g} deg/s for {params.seconds:g} s"


def check(checker: CheckContext, step: ResolvedStep[FvelParams], params: FvelParams) -> None:
    names = checker.names(step, [params.joint], (), as_keys=False, what="turning")
    if not names:
        return
    checker.motion_allowed(step, names)
    state = checker.joints[params.joint]
    target = state.position + params.velocity_deg_s * params.seconds
    lo, hi = state.limits or state.joint.limits_deg
    if not lo <= target <= hi:
        checker.errors.append(step.error(
            f"{params.joint} would turn to {target:g} deg, outside {lo:g}..{hi:g}", "seconds"))
        return
    state.position = target


def run(step: ResolvedStep[FvelParams], ex: StepContext) -> dict:
    import numpy as np

    from seqrun.arm.planner import Limits

    params = step.params
    index = ex.arm.index(params.joint)
    target = np.array(ex.read_arm().user_deg, dtype=float)
    target[index] += params.velocity_deg_s * params.seconds
    velocity, acceleration = ex.limits_in_force.maxima()
    limits = Limits.from_arm(ex.arm, speed=ex.speed,
                             velocity_deg_s={params.joint: abs(params.velocity_deg_s)},
                             max_velocity_deg_s=velocity, max_acceleration_deg_s2=acceleration)
    detail = ex.move(target, [index], limits,
                     tolerance_deg=ex.arm.control.position_tolerance_deg, timeout_s=None)
    return {**detail, "turned_deg": params.velocity_deg_s * params.seconds}


KIND = StepKind(
    name="fvel", params=FvelParams, describe=describe, check=check, run=run,
    value=one_key_value("fvel", FvelParams),
    example="fvel: {joint: j1, velocity_deg_s: 5, seconds: 2}", motion=True)
'''

SEQUENCE = """\
name: fvel
description: a joint turned at a velocity
steps:
  - reset
  - home
  - set_limits
  - fvel: {joint: j1, velocity_deg_s: 5, seconds: 2}
"""

#: What the process that imports the copy checks (argv: the project folder).
PROBE = """\
import json, sys
from pathlib import Path

import seqrun
from seqrun import schema
from seqrun.arm.description import load_arm
from seqrun.arm.poses import park_deg
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from seqrun.service.dryrun import dry_run
from seqrun.steps.registry import HANDLERS, step_kind

project = Path(sys.argv[1])
loaded = load_sequence(project / "sequences" / "fvel.yaml")
arm = load_arm(project / "arms" / "lwa3.yaml")
start = park_deg(project / "poses")
bad = load_sequence(project / "sequences" / "too_far.yaml")
run = dry_run(loaded, arm, start)
print(json.dumps({
    "package": seqrun.__file__,
    "union": "fvel" in schema.STEP_KINDS and "FvelParams" in schema.sequence_json_schema()["$defs"],
    "handler": HANDLERS["fvel"] is step_kind("fvel").run,
    "title": loaded.steps[-1].title,
    "errors": [str(e) for e in validate_sequence(loaded, arm, start).errors],
    "bad": [str(e) for e in validate_sequence(bad, arm, start).errors],
    "exit": run.result.exit_code,
    "turned": run.result.steps[-1].detail.get("turned_deg"),
}))
"""


def _copy_with_fvel(tmp_path):
    """The package copied, plus fvel.py and its registry lines; returns the registry's diff."""
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "seqrun", tree / "seqrun",
                    ignore=shutil.ignore_patterns("__pycache__", "_shipped"))
    for shipped in ("arms", "poses"):
        shutil.copytree(ROOT / shipped, tree / shipped)
    (tree / "seqrun" / "steps" / "fvel.py").write_text(FVEL, encoding="utf-8")
    registry = tree / "seqrun" / "steps" / "registry.py"
    before = registry.read_text(encoding="utf-8")
    after = before.replace("from seqrun.steps.kind import StepKind\n",
                           "from seqrun.steps import fvel\n"
                           "from seqrun.steps.kind import StepKind\n", 1)
    after = after.replace("    power_off.KIND,\n", "    power_off.KIND,\n    fvel.KIND,\n", 1)
    registry.write_text(after, encoding="utf-8")
    changed = [line for line in difflib.unified_diff(before.splitlines(), after.splitlines(),
                                                     lineterm="", n=0)
               if line[:1] in "+-" and not line.startswith(("+++", "---"))]
    return tree, changed


def test_a_new_step_kind_is_one_module_and_its_registry_lines(tmp_path):
    tree, changed = _copy_with_fvel(tmp_path)
    assert changed == ["+from seqrun.steps import fvel", "+    fvel.KIND,"]
    project = tmp_path / "project"
    (project / "sequences").mkdir(parents=True)
    shutil.copytree(ROOT / "arms", project / "arms")
    shutil.copytree(ROOT / "poses", project / "poses")
    (project / "sequences" / "fvel.yaml").write_text(SEQUENCE, encoding="utf-8")
    (project / "sequences" / "too_far.yaml").write_text(
        SEQUENCE.replace("seconds: 2}", "seconds: 100}"), encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", PROBE, str(project)], capture_output=True,
                         text=True, env=env, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr
    found = json.loads(out.stdout.splitlines()[-1])
    assert found["package"].startswith(str(tree))  # the copy, not the checkout
    assert found["union"] and found["handler"]
    assert found["title"] == "turn j1 at 5 deg/s for 2 s"
    assert found["errors"] == []
    assert len(found["bad"]) == 1 and "too_far.yaml:7:51: j1 would turn to 500" in found["bad"][0]
    assert found["exit"] == 0 and found["turned"] == 10

    # and the program itself: `seqrun validate` dry-runs it
    validate = subprocess.run([sys.executable, "-m", "seqrun", "validate",
                               str(project / "sequences" / "fvel.yaml")],
                              capture_output=True, text=True, env=env, cwd=project, timeout=300)
    assert validate.returncode == 0, validate.stdout + validate.stderr
    assert "turn j1 at 5 deg/s for 2 s" in validate.stdout

