"""The paths a sequence with ``block`` / ``rescue`` / ``always`` can take, on its flat steps.

The loader flattens a block into the step list (its steps, then its rescue, then its
always; :class:`~seqrun.steps.resolved.BlockFrame` on each says where it is written).
Validation follows the arm along the *normal path* (no rescue runs) and along one *rescue
path* per block with a rescue: the block's steps all ran and its last failed, then its
rescue, its always and everything after it. Before a rescue runs, the executor checks the
path from the arm's measured pose again (the failure may come earlier in the block).
Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TypeVar

__all__ = ["has_rescue", "normal_path", "rescue_paths"]

_S = TypeVar("_S")


def _frames(step: Any) -> tuple[Any, ...]:
    return getattr(step, "blocks", ())


def has_rescue(steps: Sequence[Any]) -> bool:
    """Whether any step is written in a block's rescue."""
    return any(frame.part == "rescue" for step in steps for frame in _frames(step))


def normal_path(steps: Sequence[_S]) -> list[_S]:
    """The steps that run when nothing fails: every step but the rescues'."""
    return [s for s in steps if all(f.part != "rescue" for f in _frames(s))]


def rescue_paths(steps: Sequence[_S]) -> dict[int, list[_S]]:
    """Block number -> the steps that run when its last step fails and its rescue runs
    (the rescues around this block's own position run too: a block in a rescue is
    reached only through that rescue)."""
    rescued_in: dict[int, set[int]] = {}  # block -> the blocks whose rescue holds it
    for step in steps:
        frames = _frames(step)
        for depth, frame in enumerate(frames):
            outer = {f.block for f in frames[:depth] if f.part == "rescue"}
            rescued_in.setdefault(frame.block, set()).update(outer)
    has_own = {f.block for s in steps for f in _frames(s) if f.part == "rescue"}
    return {block: [s for s in steps
                    if all(f.part != "rescue" or f.block == block or f.block in rescued_in[block]
                           for f in _frames(s))]
            for block in sorted(has_own)}
