"""The record of one step kind: everything seqrun knows about it, found together.

Each module ``seqrun/steps/<kind>.py`` ends with ``KIND = StepKind(...)`` and
:mod:`seqrun.steps.registry` lists it. Who uses which part:

- ``params``, ``value``, ``shorthand``, ``bare``, ``example``: :mod:`seqrun.schema` (the
  sequence file's union, the JSON Schema, the format reference, the error for a bare word);
- ``poses``, ``describe``: the loader (the pose files read and frozen with the sequence; the
  step's title for the operator when it has no label);
- ``check``: the static validation (the checks against the arm and the steps before),
  through :class:`~seqrun.steps.check_context.CheckContext`;
- ``run``: the executor (``seqrun.steps.registry.HANDLERS``), through
  :class:`~seqrun.steps.context.StepContext`.

Both contexts are protocols of this layer: a kind imports neither the validator nor the
executor, and what it receives (:class:`~seqrun.steps.resolved.ResolvedStep`) is this
layer's data too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from seqrun.steps.check_context import CheckContext
    from seqrun.steps.context import StepContext
    from seqrun.steps.params import StepParams
    from seqrun.steps.resolved import ResolvedStep

__all__ = ["StepKind", "no_files", "no_poses"]


def no_poses(params: Any) -> tuple[str, ...]:
    """A step that names no pose file."""
    return ()


def no_files(params: Any) -> tuple[str, ...]:
    """A step that reads no data file."""
    return ()


@dataclass(frozen=True)
class StepKind:
    """One step kind. ``name`` is its key in a sequence file (``move``)."""

    name: str
    #: The parameter model (a :class:`~seqrun.steps.params.StepParams`).
    params: type[StepParams]
    #: The type of the value under the step's key: the parameters or a shorthand
    #: (:func:`seqrun.steps.params.one_key_value`).
    value: Any
    #: One line for people when the step has no label, e.g. "move to pose totem".
    describe: Callable[[Any], str]
    #: Static checks: ``check(checker, step, params)`` appends errors/notes to the checker
    #: and tracks what the step does to the modules and joints.
    check: Callable[[CheckContext, ResolvedStep, Any], None]
    #: The handler: ``run(step, context) -> detail`` (into the step's report entry).
    run: Callable[[ResolvedStep, StepContext], dict | None]
    #: The shorthand forms for the docs, e.g. " Shorthand: 'move: totem' (a pose name)."
    shorthand: str = ""
    #: May be written as a bare word (``- reset``) with its default parameters.
    bare: bool = False
    #: A short example, for the error of a bare word that needs parameters.
    example: str = ""
    #: The pose files the step names (read and frozen when the sequence is loaded).
    poses: Callable[[Any], tuple[str, ...]] = no_poses
    #: The data files the step reads, relative to its sequence file (copied into the run
    #: folder's inputs/ with the sequence).
    data_files: Callable[[Any], tuple[str, ...]] = no_files
    #: The step moves the arm: the checks know where its motion starts (relative
    #: checkpoints measure from there).
    motion: bool = False
