"""The file format references in Markdown (``seqrun schema [sequence|arm|pose] --markdown``).

Generated from the models' JSON Schema, so the docs cannot drift from what the loader
accepts: ``docs/sequence-format.md`` (tests/test_schema.py checks it is up to date).
"""

from __future__ import annotations

from json import dumps as json_dumps
from typing import TYPE_CHECKING

from seqrun.schema import PARAMS_MODELS, STEP_MODELS, doc, sequence_json_schema

if TYPE_CHECKING:
    from pydantic import BaseModel

__all__ = [
    "arm_reference_markdown",
    "file_reference_markdown",
    "pose_reference_markdown",
    "reference_markdown",
]

_REFERENCE_INTRO = """\
# Sequence files

<!-- Generated from the models in seqrun/schema.py by `seqrun schema --markdown`;
     do not edit by hand (tests/test_schema.py checks it is up to date). -->

A sequence file says what the arm does, step by step. Editors with yaml-language-server
check it as you type when its first line names the schema:

```yaml
# yaml-language-server: $schema=../docs/schema/sequence.schema.json
name: Op-safe
description: From a freshly powered-on arm in Park to the Op-safe pre-grasp pose.
steps:
  - include: startup.yaml                 # reset, home, set_limits
  - confirm: Is the space around the arm clear?
  - move: {pose: totem, velocity_scale: 0.5, label: Up to Totem}
  - move: {pose: opsafe, velocity_scale: 0.5}
  - wait: {until: in_position}
  - checkpoint: {pose: opsafe}
```

`seqrun validate FILE` checks a file and its includes without moving anything:
`file:line:col: message` for each problem, exit 0 (valid), 1 (invalid) or 2 (unusable input).
The problems are listed file by file, by position within each file, the files in the order
the steps reach their first problem (a pose file's after those of the step that names it);
`seqrun run` refuses an invalid file with the same lines in the same order.

## The file

| key | | |
|---|---|---|
{top}

Each step is a mapping with one key, the step type; its value holds the step's parameters.
Every step takes an optional `label`, the text the operator sees.

## YAML as seqrun reads it

- YAML 1.2 values: only `true`/`false` are booleans (`yes`, `no`, `on`, `off` stay words, and
  where `true`/`false` is expected they are an error); `010` is ten; `1:30` is text, not 90.
- `.nan`, `.inf` are refused wherever a number is expected.
- A key given twice is an error (plain YAML silently keeps the last one).
- No tags (`!!python/...`, `!custom`, ...), no merge keys (`<<`), one document per file;
  anchors and aliases are fine within limits.

## Rules checked against the arm

- Start-up order: `reset` before `home` and before `set_limits`; `home` and `set_limits`
  before the first `move`; `reset` again after a `halt`.
- Joints must exist; the locked joint (j3) is never commanded.
- Every commanded target lies inside the joint limits in force. A joint that starts outside
  them (an arm powered off outside its limits) may only move back inside (a note).
- Velocities and limit overrides stay within the arm file's maxima.
- Every move is planned within the limits in force: the arm file's, those a `set_limits`
  wrote, and the MaxVel/MaxAcc the modules still hold from before (read back before the
  first motion; they stay stored in a module until written again or powered off). The
  dry-run table and the run report say which limit applied and where it came from.
- A move's `timeout_s` may not be shorter than the move as planned.
- A velocity move (`move_velocity`) is never open-ended: it needs `duration_s` and an
  `envelope_deg` for every joint it moves, inside the limits in force. Each joint ramps to
  its velocity, holds it until `duration_s` and brakes at the step's acceleration; where it
  comes to rest must lie inside its envelope by the position tolerance, so a wrong sign or
  too long a duration is refused at the velocity's line. The run checks every cycle that
  the measured position plus the stopping distance at the measured velocity stays inside
  the envelope and the joint's limits (else Halt). The modules' watchdog is armed before
  the first FVEL and refreshed by every exchange: if seqrun stops talking, each module stops
  by itself within the watchdog timeout (about 50 ms) plus half the refresh period
  (`can.watchdog.refresh_period_s`), i.e. after at most
  v × (timeout + refresh period) + v² / (2 × MaxAcc) of travel (0.6° for j1 at 5 deg/s with
  the shipped arm file's values). A clean end disarms it again.
- Waits (`seconds`, `timeout_s`) and move timeouts stay within the arm file's
  `control.max_wait_s`; a dry run stops after `control.max_dry_run_s` of simulated time.
- Workspace guards of the arm file hold along each move's planned trajectory (the ruckig plan
  the run streams, sampled at 100 Hz); `seqrun validate` reports the smallest clearance of each move.
- The arm file's link volumes (capsules) keep `geometry.margin_mm` from its obstacles and
  from each other along each move, and the closest pair of each move is reported. Every
  collision of a move is an error of its own (each link or tool volume, each guard's
  lowest point: the hand and the tool it carries), in the order they happen, at the
  move's line.
- End-effector targets (`move` with `position_mm`, `move_linear`) are solved by inverse
  kinematics from the joints tracked so far (the solution nearest them); an unreachable
  target is an error at its `position_mm`. The run solves again from the measured joints
  and stops (Halt) if that solution is more than `cartesian.ik_agreement_deg` from the
  validated one. A straight line is sampled every `cartesian.linear_sample_s` and every
  sample must be reachable, inside the limits in force, within the joint velocity limits
  and away from singular configurations (`cartesian.min_manipulability`); during the run
  the tool further than `max_deviation_mm` from the line is a fault.
- A checkpoint must agree with the tool pose of the joints tracked so far (the same frame
  a move's `position_mm` means: see "Tools and frames"); a relative one (`moved_mm`) with
  how far the tool moved during the last move. A checkpoint or a
  wait after a `halt` (and no `reset`) can never pass and is an error.
- Every pose a step names is checked against the arm at the pose file's own lines: it lists
  every joint (the locked one at its locked value), its `end_effector` agrees with forward
  kinematics of its joints, and a pose used as a move target lies inside the joint limits.
- Every problem is reported in one pass: a step that is wrong on its own is left out and
  the others are still checked against the arm. Only what the left-out step may have
  changed goes unchecked after it: the start-up order after a left-out `reset`, `home`,
  `set_limits`, `halt` or `power_off` (or an include that could not be read), and what
  depends on where the joints are after a left-out motion, until a move to absolute
  targets of every joint says it again.
- A run uses exactly what was validated: the sequence, its includes, the poses and the arm
  file are read once; their SHA-256 is in the run report (`inputs`).
- Validation starts from Park (`--start POSE` to choose another pose).

## Tools and frames

Positions are millimetres in the base frame: its origin where the arm is mounted on the desk,
z up (the arm stands along +z in Totem). Orientations are `rpy_deg` = [roll, pitch, yaw],
R = Rz(yaw) Ry(pitch) Rx(roll), of the frame that moves.

- **The end-effector frame** (`kinematics.tool` of the arm file, 36.9 mm beyond the last
  module's flange on the LWA 3) has its **z axis pointing back into the arm**: in Totem the
  arm points up and the end-effector's rotation is diag(1, −1, −1), rpy [180, 0, 0]. What is
  bolted to the flange sticks out along the end-effector's **−z**.
- **A tool** of the arm file (`tools:`) is a tip frame given in the end-effector frame
  (`xyz_mm`, `rpy_deg`) and a volume (`capsules`). A 120 mm probe on the flange's axis:
  `{name: probe, xyz_mm: [0, 0, -120]}`; its tip frame keeps the end-effector's axes, so it
  points along its own −z too. A tool given `rpy_deg: [180, 0, 0]` has its tip frame's z
  axis pointing out along the tool (the convention of many robot controllers).
- **One frame for every Cartesian number of a sequence**: `position_mm`/`rpy_deg` of `move`
  and `move_linear`, `frame: tool` displacements, a `checkpoint`'s position, pose or
  `moved_mm` all mean the step's `tool:`, else the arm's `default_tool`, else the
  end-effector frame. A checkpoint at the point a move went to checks that same point.
- **A tool's volume is checked as the links' are**: against the obstacles, the links it is
  not bolted to, and every workspace guard that watches `end_effector`, along every planned
  path and every control cycle, whichever tool a step names and for moves to joint angles
  too. Without `capsules` its tip line (end-effector to tip, no thickness) is checked;
  `capsules: []` marks a tip that is a point in the air (a camera's focus). A long tool
  may not fit in Park: the first move's start is then refused.

Where the tool points (base frame), and the `rpy_deg` of its tip frame that says so (the
rotation about the tool's own axis is free: any yaw for up and down):

| the tool points | end-effector, or a tool with `rpy_deg: [0, 0, 0]` | a tool with `rpy_deg: [180, 0, 0]` |
|---|---|---|
| down (−z, at the desk) | `[0, 0, 0]` | `[180, 0, 0]` |
| up (+z, as in Totem) | `[180, 0, 0]` | `[0, 0, 0]` |
| forward (+x) | `[0, -90, 0]` | `[0, 90, 0]` |
| back (−x) | `[0, 90, 0]` | `[0, -90, 0]` |
| left (+y) | `[90, 0, 0]` | `[-90, 0, 0]` |
| right (−y) | `[-90, 0, 0]` | `[90, 0, 0]` |

So "the tool pointing down" is `rpy_deg: [0, 0, 0]` (or `[0, 0, yaw]`) for the end-effector
and for tools defined without a rotation. `[180, 0, 0]` points such a tool *up*, which is
why it is unreachable near the desk; `seqrun validate` says so and gives the rpy that points
down. `seqrun ik --tool NAME` takes the same frames (`seqrun fk` prints the end-effector's).

A straight approach along the tool, checked sample by sample, is
`sequences/linear_approach.yaml`:

```yaml
  - move: {position_mm: [0, 500, 300], rpy_deg: [0, 0, 90]}   # above the spot, pointing down
  - move_linear:                        # 100 mm along the tool, i.e. along its -z: down here
      {position_mm: [0, 0, -100], relative: true, frame: tool, speed_mm_s: 20}
  - checkpoint: {moved_mm: [0, 0, -100]}                       # 100 mm down, base frame
```

## Expressions

`wait_until: {until: ...}` and `check: ...` take an expression over the run's telemetry,
read every time it is evaluated (one monitoring cycle: faults, guards and the watchdog are
checked as in any wait). It is a small language, checked when the file is read, never
handed to Python's `eval`: numbers, `true`/`false`, the names below, `+ - * /`,
comparisons (chained: `-5 < pos_deg[1] < 5`), `and`/`or`/`not`, `abs`, `min`, `max`. A
per-joint series takes the joint's number, counted from 1 as the arm file names them
(`pos_deg[2]` is j2). Units come from the names (`_deg`, `_mm`, `_deg_s`, `_s`): comparing
or adding degrees with millimetres is refused at its file:line:col; a plain number takes
the unit of what it meets.

{names}

Every step takes `monitors:`, invariants held against every reading of the arm while the
step runs (each control cycle of a move, each cycle of a wait): `{while: EXPR,
persist_cycles: N, action: halt | warn, message: ...}`. One that has not held for N
readings in a row trips: `halt` halts the arm at once and ends the run as a fault (exit 3)
naming the monitor and the values it read; `warn` gives a `monitor_tripped` event (once,
until it holds again) and the run goes on. The gripper and the motor currents
(`current_a`) are not read every cycle (each would add an exchange to every cycle of the
loop), so a monitor cannot watch them (a `wait_until` or `check` can). A monitor with a bound tighter
than the arm file's `control.max_following_error_deg` halts a lagging joint sooner than
the run's own check.

```yaml
  - move: {pose: opsafe, monitors: [{while: "abs(following_error_deg[4]) < 1.0", persist_cycles: 2}]}
  - move: {pose: capture, monitors: [{while: "tool.z_mm > 40", message: above the target}]}
  - wait_until: {until: "gripper.holding and not moving", timeout_s: 5, persist_s: 0.5}
  - wait_until: {until: "abs(vel_deg_s[1]) < 0.1", timeout_s: 3, on_timeout: continue}
  - check: {that: "tool.z_mm > 40", verifies: [REQ-CAP-012]}
```

## Parameters

A sequence may declare typed parameters under `params:`, each `name: {type, unit, min,
max, choices, default, description}` (a name is letters, digits and `_`, not starting with
a digit). `${name}` in any value of the steps is replaced by the parameter's value before
the steps are checked: a value that is exactly `${name}` takes the typed value (a number,
true/false, a pose name), `${name}` inside a longer text is replaced as text. In a flow
mapping (`{...}`) quote it (`{pose: "${target}"}`): YAML ends a plain value at `{`. An
unknown `${x}` is an error at its file:line:col. Expressions read numbers and true/false
as `params.NAME`, with the parameter's `unit` (a `float` with `unit: mm` compares with
`tool.z_mm`).

The values are the defaults, overridden by `seqrun run FILE --param name=value` or `seqrun
validate FILE --param name=value` (repeatable); a value is read by its type (`true` is not
an `int`, `12` is a number, not text) and checked against `min`, `max` and `choices`; a
bad one is one line and exit 2, and so is a parameter with no default and no `--param`.
`seqrun validate FILE` without `--param` also checks each `int` or `float` parameter with a
range at its `min` and at its `max` (one at a time, the others at their defaults; static
checks and the dry run) and names the value that fails, e.g. `params: speed = 1.0 (its
max): ...`. A run keeps the values it used in record.json and report.json, and shows them
in its report. An included file without `params:` uses the including file's.

An included file with `params:` of its own is a **template**: `include: {file: approach.yaml,
with: {to: opsafe, speed: 0.3}}` gives its values (typed as written: `0.3` is a number,
`"0.3"` text), each checked against the template's declaration at its file:line:col; the
ones not given take their defaults, and one without a default must be given. Inside the
template `${name}` and `params.NAME` read its own values; the including file's parameters
are its own again after the include, and a `with:` value may be one of them
(`speed: "${slow}"`).

```yaml
params:
  speed: {type: float, min: 0.1, max: 1.0, default: 0.5, description: velocity scale}
  target: {type: pose, default: opsafe}
  floor: {type: float, unit: mm, min: 20, max: 40, default: 30}
  mode: {type: choice, choices: [slow, fast], default: slow}
steps:
  - include: startup.yaml
  - move:
      pose: ${target}
      velocity_scale: ${speed}
      label: To ${target} at ${speed} (${mode})
      monitors: [{while: "tool.z_mm > params.floor"}]
```

| key | type | |
|---|---|---|
{parameter}

## Conditions, loops and retries

Every step may take `if: EXPR` (run it only if EXPR holds at its start) or `skip_if: EXPR`
(skip it if EXPR holds), `repeat: {count: N}` or `repeat: {while: EXPR, max: N}` (run it
again while EXPR holds, checked before each iteration; `max` is required, and EXPR still
holding after `max` iterations ends the run as a fault), and `retry: {times: N, delay_s:
S}` (try it again, after S seconds of monitored waiting, when it failed in a way that may
be retried). The expressions are those of `wait_until` and `check` (see "Expressions"),
checked when the file is read, each problem at its file:line:col, and read from one
reading of the arm when needed; counts are whole numbers (`true` is not one). A skipped
step is reported as `skipped` with its condition and the value it had (a `step_skipped`
event, the terminal line, report.json and report.html); each iteration shows as
`[5/9] label (2/3)` (with while: `(2, at most 10)`); each retry is a `step_retry` event and a line of the step's report.

Only `check`, `wait_until`, `checkpoint` and `check_gripper` take `retry`, and only a
failed measurement is retried: a check that did not hold, a wait_until that timed out, a
checkpoint outside its tolerance, a gripper check that failed. A module fault, a Halt, a
guard or monitor halt and an operator abort are never retried (docs/safety.md, "What may
be retried"). Validation follows one path of the arm, so steps that move it (move,
move_linear, move_trajectory, move_velocity), that change what the modules are told
(reset, home, set_limits, halt, power_off) or that speak to the other arms (signal,
wait_for) take no `if`, `skip_if` or `repeat`; an include takes none of these keys (put
them on its steps). The dry run takes one path too: `seqrun validate` lists each branch
it did not take (a condition that was never true or never false, a retry never needed)
under "not verified", and so does its `--json` (`dry_run.not_verified`); a branch that a
dry run at a numeric parameter's `min` or `max` took (see "Parameters") is not listed.

`on_fail: pause` (on the same four kinds, outside blocks and campaigns of several arms)
hands the failure to the operator once the step's own `retry` is spent, the arm at rest:
Retry runs the step again (failing again, it asks again: the step's own retries are not
spent twice), Skip leaves it failed ("skipped by the operator") and goes on
once the rest of the sequence is checked from the measured pose, Abort ends the run as an
operator abort (exit 130); each answer is an `operator_choice` event and a line of the
step's report. A fault is never offered, `--yes` never answers it and the dry run never
pauses (docs/safety.md, "Who answers what"). The default, `on_fail: fail`, ends the run.

```yaml
  - grip: {part_width_mm: 30, force_n: 40, if: "not gripper.holding"}   # nothing held yet
  - confirm: {prompt: "Is the desk clear?", skip_if: "tool.z_mm > 400"}
  - wait: {seconds: 0.5, repeat: {count: 3}}                     # [5/9] wait 0.5 s (2/3)
  - wait: {seconds: 1, repeat: {while: "abs(vel_deg_s[4]) > 0.05", max: 10}}
  - wait_until: {until: "gripper.holding", timeout_s: 2, retry: {times: 2, delay_s: 1}}
  - checkpoint: {pose: capture, retry: {times: 1, delay_s: 0.5}}
  - check: {that: "gripper.holding", on_fail: pause}     # Retry / Skip / Abort
```

## Blocks: rescue and always

A `block` groups steps (`steps:`, at least one) with a `rescue:` (steps run when a step of
the block fails in a way a rescue may follow) and an `always:` (steps run after the block
and its rescue, passed or failed), as Ansible's block/rescue/always and RAPID's ERROR
handlers do. Either list may be left out, never empty; a block takes a `label` and no
other key (put `if`, `monitors`, `retry` ... on its steps); blocks nest, in any of the
three lists.

A rescue follows only the failures `retry` follows: a `check` that did not hold, a
`wait_until` that timed out (`on_timeout: fail`), a `checkpoint` or `check_gripper` out of
tolerance. Nothing is halted then: the block's later steps are skipped, its rescue runs,
then its always. If the rescue passes, the block is reported `rescued` (the failed step
stays `failed` in the report, with its error) and the run goes on; if the rescue fails, or
there is none, the block fails and so does the block around it (whose rescue may take
it), else the run, after the always steps, ending as that failure would without a block
(exit 3, Halt with the arm at rest). A module fault, a Halt (guard, monitor `halt`, arm
separation, operator STOP), a lost bus and an operator abort are never rescued: the run
ends at once as without a block, and neither the rescue nor the always moves the arm
(docs/safety.md, "What a rescue may follow"; the rescue then needs the operator).

Validation follows the normal path (no rescue runs) and, for each block with a rescue,
the path where the block's last step fails (its steps, its rescue, its always, what
follows), every plan-time check on both. In a run, after a recoverable failure and before
the next step, the steps the run goes on with are checked again from the measured arm, as
the preflight does (a `block_recheck` event): the failure may come earlier in the block,
and nothing moves if they are not valid from there. Every step in a block is reported
with where it is written (`block: "block 1 (Capture) rescue"`, nested ones joined with
` > `); report.json and the dry run's `--json` carry `blocks` (each block's status:
passed, rescued, failed or not run), the terminal a line per block; events
`block_step_failed` and `block_finished`. A rescue the dry run did not run is listed under
"not verified": rehearse it with a failing `check` (a measurement a simulator fault cannot
make fail; `--sim-fault` rehearses the faults, which are never rescued). In a campaign of
several arms a block takes no `rescue` or `always`: the arms are proven clear of each other
along the normal path's timing, which a failure changes.

```yaml
  - block:
      label: Capture
      steps:
        - move: {pose: capture, velocity_scale: 0.3}
        - wait_until: {until: "gripper.holding", timeout_s: 2}
        - checkpoint: {pose: capture}
      rescue:
        - move: {pose: opsafe, velocity_scale: 0.3, label: Retreat to Op-safe}
      always:
        - release: {width_mm: 60}
```

## Steps
"""


def _expression_names() -> str:
    """The table of the names an expression reads."""
    from seqrun.steps.expressions import JOINT_SERIES, NAMES

    meaning = {
        "pos_deg": "measured position of joint J, user degrees",
        "vel_deg_s": "measured velocity of joint J (slope of the last two readings)",
        "following_error_deg": "commanded minus measured position of joint J (no value "
                               "before the first move or after a Halt)",
        "target_deg": "what joint J was last commanded",
        "current_a": "the actual motor current of joint J's module (PowerCube Cur), read "
                     "when the expression is evaluated: in checks, waits and conditions, "
                     "not in monitors (not read in the control loop)",
        "tool.x_mm": "the end-effector's position (forward kinematics of the measured "
                     "joints), base frame", "tool.y_mm": "", "tool.z_mm": "",
        "tool.roll_deg": "the end-effector's roll, pitch, yaw (docs: Tools and frames)",
        "tool.pitch_deg": "", "tool.yaw_deg": "",
        "gripper.width_mm": "the gripper's opening (arm file's `gripper`)",
        "gripper.holding": "the jaws at rest at their current limit: a part is held",
        "gripper.moving": "the jaws move",
        "step_time_s": "seconds since the step began",
        "sequence_time_s": "seconds since the run began",
        "moving": "any joint reports motion",
    }
    rows = ["| name | type | meaning |", "|---|---|---|"]
    rows += [f"| `{name}[J]` | number, {unit} | {meaning[name]} |"
             for name, unit in JOINT_SERIES.items()]
    rows += [f"| `{name}` | {'true/false' if kind == 'bool' else f'number, {unit}'} | "
             f"{meaning[name] or '(as above)'} |" for name, (kind, unit) in NAMES.items()]
    return "\n".join(rows)


def _type_text(prop: dict, defs: dict) -> str:
    if "$ref" in prop:
        return "mapping"
    if "anyOf" in prop:
        kinds = [_type_text(p, defs) for p in prop["anyOf"] if p.get("type") != "null"]
        return " or ".join(kinds)
    if "oneOf" in prop:
        return " or ".join(_type_text(p, defs) for p in prop["oneOf"])
    if "const" in prop:
        return f"`{prop['const']}`"
    if "enum" in prop:
        return " or ".join(f"`{v}`" for v in prop["enum"])
    kind = prop.get("type")
    if kind == "array":
        items = _type_text(prop.get("items", {}), defs)
        n = prop.get("minItems")
        if n is not None and n == prop.get("maxItems"):
            return f"[{n} × {items}]"
        return f"list of {items}"
    if kind == "object":
        return f"{{joint: {_type_text(prop.get('additionalProperties', {}), defs)}}}"
    bounds = []
    if "exclusiveMinimum" in prop:
        bounds.append(f"> {prop['exclusiveMinimum']}")
    if "maximum" in prop:
        bounds.append(f"≤ {prop['maximum']}")
    names: dict[str | None, str] = {"number": "number", "string": "text",
                                    "boolean": "true/false", "integer": "whole number"}
    text = names.get(kind, "value")  # (kind is None when the schema gives no type)
    return text + (" " + ", ".join(bounds) if bounds else "")


def reference_markdown() -> str:
    """The sequence format reference (docs/sequence-format.md), from the models."""
    schema = sequence_json_schema()
    defs = schema["$defs"]

    def rows(definition: dict) -> str:
        required = set(definition.get("required", []))
        lines = []
        props = definition["properties"]
        for key in sorted(props, key=lambda k: k == "label"):  # label last
            prop = props[key]
            if key in ("steps", "rescue", "always"):   # (a block's lists too)
                need = " — required" if key in required else ""
                lines.append(f"| `{key}` | list of steps (below){need} | "
                             f"{prop.get('description', '')} |")
                continue
            if key == "params":
                lines.append(f"| `params` | {{name: parameter}} (see Parameters) | "
                             f"{prop.get('description', '')} |")
                continue
            if key == "with":
                lines.append(f"| `with` | {{parameter: value}} (see Parameters) | "
                             f"{prop.get('description', '')} |")
                continue
            default = ("required" if key in required else
                       "" if prop.get("default") in (None, {}) else
                       f"default `{json_dumps(prop['default'])}`")
            lines.append(f"| `{key}` | {_type_text(prop, defs)}"
                         f"{' — ' + default if default else ''} | "
                         f"{prop.get('description', '')} |")
        return "\n".join(lines)

    parts = [_REFERENCE_INTRO.replace("{top}", rows(schema))
             .replace("{names}", _expression_names())
             .replace("{parameter}", rows(defs["ParameterSpec"]))]
    for kind, model in PARAMS_MODELS.items():
        step = defs[STEP_MODELS[kind].__name__]["properties"][kind]
        parts.append(f"### `{kind}`\n\n{doc(model)}\n")
        shorthand = step["description"].split(" Shorthand: ", 1)
        if len(shorthand) == 2:
            parts.append(f"Shorthand: {shorthand[1]}\n")
        definition = defs[model.__name__]
        if "oneOf" in definition:
            choices = [" + ".join(f"`{k}`" for k in alt["required"])
                       for alt in definition["oneOf"]]
            parts.append(f"Give exactly one of: {' or '.join(choices)}.\n")
        parts.append("| key | type | |\n|---|---|---|\n" + rows(definition) + "\n")
    return "\n".join(parts)


def file_reference_markdown(model: type[BaseModel], title: str, intro: str) -> str:
    """A reference of a file format given by a pydantic model (pose files, arm files): one
    row per key, nested mappings as dotted keys, from the model's JSON Schema."""
    schema = model.model_json_schema()
    defs = schema.get("$defs", {})

    def resolve(prop: dict) -> dict:
        if "$ref" in prop:
            return defs[prop["$ref"].rsplit("/", 1)[-1]]
        if "allOf" in prop and len(prop["allOf"]) == 1:
            return {**resolve(prop["allOf"][0]), **{k: v for k, v in prop.items()
                                                   if k != "allOf"}}
        return prop

    def kind(prop: dict) -> str:
        if "anyOf" in prop:
            return " or ".join(kind(p) for p in prop["anyOf"] if p.get("type") != "null")
        if "enum" in prop:
            return " or ".join(f"`{v}`" for v in prop["enum"])
        if "const" in prop:
            return f"`{prop['const']}`"
        if prop.get("type") == "array":
            items = prop.get("prefixItems") or []
            if items:
                return f"[{len(items)} × {kind(items[0])}]"
            return f"list of {kind(resolve(prop.get('items', {})))}"
        if prop.get("type") == "object" and isinstance(prop.get("additionalProperties"), dict):
            return f"{{name: {kind(resolve(prop['additionalProperties']))}}}"
        if prop.get("format") == "date-time":
            return "date and time (ISO 8601)"
        return {"number": "number", "string": "text", "boolean": "true/false",
                "integer": "whole number", "object": "mapping"}.get(prop.get("type", ""),
                                                                     "value")

    rows: list[str] = []

    def walk(definition: dict, prefix: str) -> None:
        required = set(definition.get("required", []))
        for key, raw in definition.get("properties", {}).items():
            prop = resolve(raw)
            name = f"{prefix}{key}"
            default = ("required" if key in required else
                       "" if raw.get("default") in (None, "") or isinstance(
                           raw.get("default"), (dict, list)) and key not in ("rpy_deg",) else
                       f"default `{raw['default']}`")
            description = raw.get("description") or prop.get("description") or ""
            if prop.get("properties"):
                rows.append(f"| `{name}` | mapping{' — ' + default if default else ''} | "
                            f"{description} |")
                walk(prop, name + ".")
                continue
            rows.append(f"| `{name}` | {kind(prop)}{' — ' + default if default else ''} | "
                        f"{description} |")

    walk(schema, "")
    return (f"# {title}\n\n{intro}\n\n| key | type | |\n|---|---|---|\n" + "\n".join(rows)
            + "\n")


def pose_reference_markdown() -> str:
    """The pose file reference (``seqrun schema pose --markdown``)."""
    from seqrun.arm.poses import PoseFile

    return file_reference_markdown(
        PoseFile, "Pose files",
        "`poses/<name>.yaml`: a named joint configuration in user degrees (Totem = zeros). "
        "It lists every joint of the arm, the locked one at its locked value; "
        "`end_effector` is what forward kinematics gives for those joints and is checked "
        "against them. `seqrun pose save NAME` writes one from the arm.")


def arm_reference_markdown() -> str:
    """The arm file reference (``seqrun schema arm --markdown``)."""
    from seqrun.arm.description import ArmDescription

    return file_reference_markdown(
        ArmDescription, "Arm files",
        "`arms/<name>.yaml`: every number about the arm (joints, limits, offsets, "
        "kinematics, CAN and control-loop settings, workspace guards, tools and volumes). "
        "Angles in degrees, user coordinates. The end-effector frame's z axis points back "
        "into the arm: a tool on the flange's axis ends at `xyz_mm: [0, 0, -length]` and "
        "points along its frame's -z (docs/sequence-format.md, 'Tools and frames', has the "
        "table of directions and rpy). A tool's `capsules` are its volume, checked against "
        "the obstacles, the links it is not bolted to and the guards that watch "
        "end_effector; without them its tip line is checked.")
