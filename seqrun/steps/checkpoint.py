"""checkpoint: forward kinematics of the measured joints against an expected tool pose, or
how far the tool moved during the last move (``moved_mm``). Every Cartesian number of a
sequence means the same frame: the step's tool, else the arm's default_tool, else the
end-effector."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, ClassVar, Literal

from pydantic import ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

from seqrun.errors import RunAborted
from seqrun.steps.kind import StepKind
from seqrun.steps.params import PoseName, Positive, StepParams, Vector3, one_key_value

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.description import ArmDescription
    from seqrun.arm.poses import PoseSource
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.resolved import ResolvedStep


class CheckpointParams(StepParams):
    """Check the measured tool pose (forward kinematics of the joints) against an expected
    one; the run stops if it is off by more than the tolerances. The tool is the step's
    tool:, else the arm's default_tool, else the end-effector frame: the frame a move's
    position_mm means, so a checkpoint at the point a move went to checks that point."""

    kind: ClassVar[str] = "checkpoint"
    yaml_name: ClassVar[str] = "checkpoint"
    model_config = ConfigDict(json_schema_extra={"oneOf": [
        {"required": ["pose"]}, {"required": ["position_mm", "rpy_deg"]},
        {"required": ["moved_mm"]}]})

    pose: PoseName | None = Field(
        None, description="Expect the tool where this pose file puts it.")
    moved_mm: Vector3 | None = Field(
        None, description="Relative checkpoint: the tool moved by this [x, y, z] in mm during "
                          "the last move before it (from where that move started), in the "
                          "base or the tool frame (frame; tool: the tool's frame where the "
                          "move started), e.g. [0, 0, -300] with frame: tool.")
    frame: Literal["base", "tool"] = Field(
        "base", description="With moved_mm: the frame the displacement is given in.")
    tool: str | None = Field(None, min_length=1, description="The arm file's tool whose tip "
                                                             "frame is checked, as a move's "
                                                             "tool: is (default: the arm's "
                                                             "default_tool, else the "
                                                             "end-effector frame).")
    position_mm: Vector3 | None = Field(
        None, description="Expected tool position [x, y, z] in mm (base frame): the point a "
                          "move to this position_mm with the same tool puts there.")
    rpy_deg: Vector3 | None = Field(
        None, description="Expected tool orientation [roll, pitch, yaw] in degrees, "
                          "R = Rz(yaw) Ry(pitch) Rx(roll).")
    position_tolerance_mm: Positive = Field(
        7.0, description="Largest allowed distance from the expected position, mm. The "
                         "default covers the worst case of a 0.2° in-position error on every "
                         "joint of the LWA 3 at Op-safe (6.2 mm).")
    angle_tolerance_deg: Positive = Field(
        1.5, description="Largest allowed rotation angle between expected and measured "
                         "orientation, degrees (default: covers 0.2° per joint, 1.2°).")

    @model_validator(mode="after")
    def _one(self) -> CheckpointParams:
        if self.moved_mm is not None:
            others = [k for k in ("pose", "position_mm", "rpy_deg") if getattr(self, k) is not None]
            if others:
                raise PydanticCustomError("checkpoint_what", "a relative checkpoint (moved_mm) "
                                          "takes no {others}", {"others": ", ".join(others)})
            return self
        if self.frame != "base":
            raise PydanticCustomError("checkpoint_what", "frame belongs to a relative "
                                                         "checkpoint (moved_mm)")
        explicit = self.position_mm is not None or self.rpy_deg is not None
        if self.pose is not None and explicit:
            raise PydanticCustomError("checkpoint_what", "a checkpoint takes either 'pose' or "
                                                         "'position_mm' with 'rpy_deg', not both")
        if self.pose is None and (self.position_mm is None or self.rpy_deg is None):
            missing = "rpy_deg" if self.position_mm is not None else (
                "position_mm" if self.rpy_deg is not None else "")
            raise PydanticCustomError(
                "checkpoint_what", "a checkpoint with position_mm needs rpy_deg too"
                if missing == "rpy_deg" else "a checkpoint with rpy_deg needs position_mm too"
                if missing else "a checkpoint needs either 'pose' or 'position_mm' and 'rpy_deg'")
        return self

    @classmethod
    def from_shorthand(cls, value: Any) -> StepParams:
        return value if isinstance(value, cls) else cls(pose=value)


def describe(params: CheckpointParams) -> str:
    if params.moved_mm is not None:
        xyz = ", ".join(f"{v:g}" for v in params.moved_mm)
        return f"checkpoint: the tool moved [{xyz}] mm ({params.frame} frame)"
    what = f" (tool {params.tool})" if params.tool is not None else ""
    return (f"checkpoint: pose {params.pose}{what}" if params.pose is not None
            else f"checkpoint: tool pose{what}")


def _frame_name(arm: ArmDescription, tool: str | None) -> str:
    """What a checkpoint checks, for messages: "the tool probe" or "the end-effector"."""
    found = arm.tool(tool)
    return "the end-effector" if found is None else f"the tool {found.name}"


def poses(params: CheckpointParams) -> tuple[str, ...]:
    return (params.pose,) if params.pose is not None else ()


def resolve_checkpoint(params: CheckpointParams, arm: ArmDescription, poses: PoseSource
                       ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Expected tool frame of a checkpoint (the step's tool, else the arm's default tool,
    else the end-effector: the frame a move's position_mm means): ``(position_mm (3,),
    rotation (3, 3), position_tolerance_mm, angle_tolerance_deg)``. ``poses``: the
    sequence's frozen poses (a run uses only these) or a pose folder. KeyError for a tool
    the arm does not define."""
    import numpy as np

    from seqrun.arm.cartesian import solver_for, tool_pose
    from seqrun.arm.kinematics import matrix_from_rpy, user_joint_values
    from seqrun.arm.poses import pose_joints_deg

    if params.pose is not None:
        joints = pose_joints_deg(params.pose, poses)
        joints = {j.name: (j.locked if j.locked is not None else joints.get(j.name, 0.0))
                  for j in arm.joints}
        frame = tool_pose(solver_for(arm, params.tool), user_joint_values(arm, joints))
        position, rotation = frame[:3, 3], frame[:3, :3]
    else:
        assert params.position_mm is not None and params.rpy_deg is not None
        position = np.asarray(params.position_mm, dtype=float)
        rotation = matrix_from_rpy(np.radians(params.rpy_deg))
    return (np.array(position, dtype=float), np.array(rotation, dtype=float),
            float(params.position_tolerance_mm), float(params.angle_tolerance_deg))


# --------------------------------------------------------------------------- static checks
def check(checker: CheckContext,
          step: ResolvedStep[CheckpointParams], params: CheckpointParams) -> None:
    if params.moved_mm is not None:
        _relative_checkpoint(checker, step, params)
        return
    import numpy as np

    from seqrun.arm.cartesian import tool_pose
    from seqrun.arm.kinematics import orientation_error, rpy_from_matrix
    from seqrun.errors import SequenceInvalid, UserInputError
    from seqrun.formatting import format_number as f

    checker.after_halt(step, "checkpoint")
    if params.pose is not None and checker.pose(step, params.pose, target=False) is None:
        return  # unknown pose or its file has errors: reported already
    solver = checker.tool_solver(step, params)
    if solver is None:
        return  # an unknown tool: reported
    try:
        position, rotation, pos_tol, ang_tol = resolve_checkpoint(params, checker.arm,
                                                                  checker.poses)
    except (UserInputError, SequenceInvalid):
        return  # reported when the sequence was loaded
    except ValueError as exc:
        checker.errors.append(step.error(f"checkpoint: {exc}", "pose"))
        return
    if checker.position_unknown:
        return  # where the joints are after the moves before is not known
    if _lost(checker, step):
        return
    frame = tool_pose(solver, checker.tracked())
    distance = float(np.linalg.norm(frame[:3, 3] - position))
    angle = math.degrees(float(orientation_error(rotation, frame[:3, :3])))
    if distance > pos_tol or angle > ang_tol:
        at = ", ".join(f(v) for v in frame[:3, 3])
        rpy = ", ".join(f(v) for v in np.degrees(rpy_from_matrix(frame[:3, :3])))
        checker.errors.append(step.error(
            f"this checkpoint cannot pass: after the moves before it "
            f"{_frame_name(checker.arm, params.tool)} is at "
            f"[{at}] mm, rpy [{rpy}]°, {f(distance)} mm and {f(angle)}° from the "
            f"expected pose (tolerances {f(pos_tol)} mm, {f(ang_tol)}°)"))


def _lost(checker: CheckContext, step: ResolvedStep[CheckpointParams]) -> bool:
    """After a target that cannot be reached the run ends there: a note, not a second
    error about where the arm would be (it stays where the step before left it)."""
    lost = checker.lost_at
    if lost is None:
        return False
    checker.notes.append(step.error(f"not checked before the run: the run cannot get past "
                                    f"step {lost.number} ({lost.location})"))
    return True


def _relative_checkpoint(checker: CheckContext, step: ResolvedStep[CheckpointParams],
                         params: CheckpointParams) -> None:
    """'The tool moved 50 mm along z': the tracked tool pose now against where the last
    move started."""
    import numpy as np

    from seqrun.arm.cartesian import displacement, tool_pose
    from seqrun.formatting import format_number as f

    assert params.moved_mm is not None  # (check() comes here only for a moved_mm checkpoint)
    if checker.position_unknown or _lost(checker, step):
        return  # where the last move took the tool is not known
    if checker.motion_start_deg is None:
        checker.errors.append(step.error("a relative checkpoint (moved_mm) needs a move before "
                                         "it", "moved_mm"))
        return
    solver = checker.tool_solver(step, params)
    if solver is None:
        return
    moved = displacement(tool_pose(solver, checker.motion_start_deg),
                         tool_pose(solver, checker.tracked()), params.frame)
    off = float(np.linalg.norm(moved - np.asarray(params.moved_mm)))
    if off > params.position_tolerance_mm:
        checker.errors.append(step.error(
            f"this checkpoint cannot pass: the last move takes the tool by "
            f"[{', '.join(f(round(float(v), 3) + 0.0) for v in moved)}] mm "
            f"({params.frame} frame), {f(off)} mm "
            f"from the expected [{', '.join(f(v) for v in params.moved_mm)}] "
            f"(tolerance {f(params.position_tolerance_mm)} mm)", "moved_mm"))


# --------------------------------------------------------------------------- run
def run(step: ResolvedStep[CheckpointParams], ex: StepContext) -> dict:
    import numpy as np

    from seqrun.arm import kinematics
    from seqrun.formatting import format_number

    if step.params.moved_mm is not None:
        return _relative(step, ex)
    from seqrun.arm.cartesian import solver_for, tool_pose

    position, rotation, pos_tol, ang_tol = resolve_checkpoint(step.params, ex.arm, ex.poses)
    measured = ex.monitor()
    T = tool_pose(solver_for(ex.arm, step.params.tool), measured.user_deg)
    reached = T[:3, 3]
    pos_err = float(np.linalg.norm(reached - np.asarray(position)))
    ang_err = math.degrees(float(kinematics.orientation_error(np.asarray(rotation), T[:3, :3])))
    detail = {
        "expected_position_mm": [round(float(x), 3) for x in position],
        "reached_position_mm": [round(float(x), 3) for x in reached],
        "reached_rpy_deg": [round(float(x), 3)
                            for x in np.degrees(kinematics.rpy_from_matrix(T[:3, :3]))],
        "position_error_mm": round(pos_err, 3), "angle_error_deg": round(ang_err, 4),
        "position_tolerance_mm": pos_tol, "angle_tolerance_deg": ang_tol,
    }
    tool = ex.arm.tool(step.params.tool)
    if tool is not None:
        detail["tool"] = tool.name
    ex.emit("checkpoint", **detail)
    if pos_err > pos_tol or ang_err > ang_tol:
        raise RunAborted("checkpoint",
                         f"checkpoint failed: {_frame_name(ex.arm, step.params.tool)} "
                         f"{format_number(pos_err)} mm "
                         f"(tolerance {format_number(pos_tol)} mm) and "
                         f"{format_number(ang_err)}° (tolerance {format_number(ang_tol)}°) "
                         "from the expected pose",
                         detail=detail, retryable=True)
    return detail


def _relative(step: ResolvedStep[CheckpointParams], ex: StepContext) -> dict:
    """'The tool moved [x, y, z] mm' since the last move started (measured joints)."""
    import numpy as np

    from seqrun.arm.cartesian import displacement, solver_for, tool_pose

    params = step.params
    assert params.moved_mm is not None  # (run() comes here only for a moved_mm checkpoint)
    measured = ex.monitor()
    if ex.motion_start_deg is None:
        raise RunAborted("checkpoint", "relative checkpoint: no move before it in this run")
    solver = solver_for(ex.arm, params.tool)
    moved = displacement(tool_pose(solver, ex.motion_start_deg),
                         tool_pose(solver, measured.user_deg), params.frame)
    off = float(np.linalg.norm(moved - np.asarray(params.moved_mm)))
    detail = {"expected_moved_mm": [round(float(x), 3) for x in params.moved_mm],
              "moved_mm": [round(float(x), 3) for x in moved], "frame": params.frame,
              "displacement_error_mm": round(off, 3),
              "position_tolerance_mm": params.position_tolerance_mm}
    ex.emit("checkpoint", **detail)
    if off > params.position_tolerance_mm:
        raise RunAborted("checkpoint",
                         f"relative checkpoint failed: the tool moved {detail['moved_mm']} mm "
                         f"({params.frame} frame), {off:.3f} mm from the expected "
                         f"{detail['expected_moved_mm']} (tolerance "
                         f"{params.position_tolerance_mm} mm)", detail=detail,
                         retryable=True)
    return detail


KIND = StepKind(
    name="checkpoint", params=CheckpointParams, describe=describe, check=check, run=run,
    poses=poses, value=one_key_value("checkpoint", CheckpointParams, text=("pose", PoseName)),
    shorthand=" Shorthand: 'checkpoint: opsafe' (a pose).", example="checkpoint: opsafe")
