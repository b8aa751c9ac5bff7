"""``block`` / ``rescue`` / ``always`` while a run goes: which step runs next, and how each
block ended.

The loader flattened each block into the step list (its steps, rescue, always), every step
knowing the blocks it is written in (:class:`~seqrun.steps.resolved.BlockFrame`). A step
of a block that fails in a way that may be recovered (:func:`recoverable`) marks its
block; the block's later steps are skipped, its rescue runs, then its always. When the
run leaves a block, the block ends: passed, rescued (it failed and its rescue passed) or
failed; a failed block fails the block around it (whose rescue may take it), or the run.
Every other failure (a module fault, a Halt, a lost bus, an operator abort) never comes
here: the run ends at once, as without a block (docs/safety.md, 'What a rescue may
follow'). A sequence without blocks never creates this.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from seqrun.errors import RunAborted
from seqrun.results import UntakenBranch

if TYPE_CHECKING:
    from seqrun.execution.stops import StopControl
    from seqrun.results import StepResult
    from seqrun.steps.resolved import BlockFrame, ResolvedStep

__all__ = ["BlockFailure", "BlockRun", "recoverable"]


def recoverable(exc: BaseException, stops: StopControl) -> bool:
    """A failure a rescue may follow: a measurement that did not meet its bound while
    nothing moved (what ``retry`` may follow too), with no Halt or abort pending."""
    return (isinstance(exc, RunAborted) and exc.retryable and stops.halt_request is None
            and not stops.aborts)


@dataclass
class BlockFailure:
    """A recoverable failure that ended a block (and maybe the run)."""

    step: ResolvedStep[Any]
    result: StepResult
    error: RunAborted


@dataclass
class _Block:
    frame: BlockFrame            # where it is written (part: of its first step)
    outer: tuple[BlockFrame, ...]  # the blocks around it, outermost first
    has_rescue: bool = False
    first_rescue: int | None = None  # the number of its first rescue step
    #: the part whose step failed ("steps", "rescue", "always"), with the first failure
    failed: dict[str, BlockFailure] = field(default_factory=dict)
    entered: bool = False


class BlockRun:
    """The blocks of one run: see the module docstring."""

    def __init__(self, emit: Any, steps: list[ResolvedStep[Any]]) -> None:
        self.emit = emit
        self._blocks: dict[int, _Block] = {}
        for step in steps:
            for depth, frame in enumerate(step.blocks):
                block = self._blocks.setdefault(frame.block,
                                                _Block(frame, tuple(step.blocks[:depth])))
                if frame.part == "rescue" and depth == len(step.blocks) - 1:
                    block.has_rescue = True
                    if block.first_rescue is None:
                        block.first_rescue = step.number
        self._open: tuple[BlockFrame, ...] = ()
        #: The failure no block rescued: the run ends failed with it (after the always
        #: steps of the blocks it left).
        self.failure: BlockFailure | None = None
        #: How each block ended, in the order they ended (for the report).
        self.outcomes: list[dict[str, Any]] = []

    # ------------------------------------------------------------------ the next step
    def enter(self, step: ResolvedStep[Any]) -> bool:
        """The blocks the run leaves before ``step`` end; whether ``step`` runs."""
        self._leave_to(step.blocks)
        if self.failure is not None:
            return False
        for frame in step.blocks:
            block = self._blocks[frame.block]
            if frame.part == "steps" and "steps" in block.failed:
                return False
            if frame.part == "rescue" and ("steps" not in block.failed
                                           or "rescue" in block.failed):
                return False
            if frame.part == "always" and "always" in block.failed:
                return False
        for frame in step.blocks:
            self._blocks[frame.block].entered = True
        return True

    def path(self, steps: list[ResolvedStep[Any]]) -> list[ResolvedStep[Any]]:
        """Which of ``steps`` (those after the step just entered) run if none fails."""
        saved = ({n: (dict(b.failed), b.entered) for n, b in self._blocks.items()},
                 self._open, self.failure, list(self.outcomes), self.emit)
        self.emit = _quiet
        try:
            return [s for s in steps if self.enter(s)]
        finally:
            for number, (failed, entered) in saved[0].items():
                self._blocks[number].failed, self._blocks[number].entered = failed, entered
            self._open, self.failure, self.outcomes, self.emit = saved[1:]

    def finish(self) -> None:
        """The run is past its last step: every block still open ends."""
        self._leave_to(())

    def fail(self, step: ResolvedStep[Any], result: StepResult, exc: RunAborted) -> None:
        """``step``, written in a block, failed in a way that may be recovered."""
        frame = step.blocks[-1]
        block = self._blocks[frame.block]
        failure = BlockFailure(step, result, exc)
        block.failed.setdefault(frame.part, failure)
        self.emit("block_step_failed", block=frame.block, part=frame.part,
                  location=_where(block.frame), cause=exc.cause, message=str(exc),
                  rescue=frame.part == "steps" and block.has_rescue)

    def rescue_starts(self, step: ResolvedStep[Any]) -> bool:
        """Whether ``step`` is the first step of a block's rescue."""
        return any(self._blocks[f.block].first_rescue == step.number
                   for f in step.blocks if f.part == "rescue")

    # ------------------------------------------------------------------ ending blocks
    def _leave_to(self, frames: tuple[BlockFrame, ...]) -> None:
        keep = 0
        while (keep < len(frames) and keep < len(self._open)
               and frames[keep].block == self._open[keep].block):
            keep += 1
        for frame in reversed(self._open[keep:]):
            self._end(self._blocks[frame.block])
        self._open = frames

    def _end(self, block: _Block) -> None:
        failed = block.failed
        if not block.entered:
            status = "not run"
        elif not failed:
            status = "passed"
        elif set(failed) == {"steps"} and block.has_rescue:
            status = "rescued"
        else:
            status = "failed"
        first = failed.get("steps") or failed.get("rescue") or failed.get("always")
        self.outcomes.append({"block": block.frame.block, "label": block.frame.title,
                              "location": _where(block.frame), "status": status,
                              **({"failed_step": first.step.number} if first else {})})
        self.emit("block_finished", block=block.frame.block, label=block.frame.title,
                  location=_where(block.frame), status=status,
                  failed_step=first.step.number if first else None)
        if status != "failed" or first is None:
            return
        # the failure goes on to the block around this one, else to the run
        last = failed.get("always") or failed.get("rescue") or first
        if block.outer:
            around = block.outer[-1]
            self._blocks[around.block].failed.setdefault(around.part, last)
        elif self.failure is None:
            self.failure = last

    # ------------------------------------------------------------------ coverage
    def not_taken(self) -> list[UntakenBranch]:
        """The rescues this run never ran (what a dry run lists as not verified)."""
        return [UntakenBranch(block.first_rescue, "rescue", None,
                              f"step {block.first_rescue} ({_where(block.frame)}): the "
                              f"rescue of block {block.frame.block} never ran (no step of "
                              "the block failed in a way a rescue follows), so it was not "
                              "exercised (rehearse it with a check in the block that fails: a fault "
                              "is never rescued)")
                for block in self._blocks.values()
                if block.first_rescue is not None and "steps" not in block.failed]


def _quiet(*_args: Any, **_data: Any) -> None:
    """No event (a path worked out ahead)."""


def _where(frame: BlockFrame) -> str:
    loc = frame.location
    return f"{loc.file}:{loc.line}:{loc.column}"
