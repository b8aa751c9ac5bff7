"""What a step kind receives: one step as the loader resolved it, and the poses frozen with it.

:class:`ResolvedStep` is one step of a sequence with its includes expanded: its validated
parameters, where it is written (``file:line:col`` of every value) and its title.
:class:`FrozenPose` is a pose file as it was read when the sequence was loaded: the run
uses these, never the file again. :mod:`seqrun.sequence.loader` builds both; a kind's
``check`` and ``run`` read them. Data only: no pydantic model, no maths, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Mapping
from typing import Any, Generic, TypeVar

from seqrun.errors import SourceError
from seqrun.steps.params import StepParams
from seqrun.yamlsource import Document, Location

__all__ = ["BlockFrame", "FrozenPose", "ResolvedStep"]


@dataclass(frozen=True)
class BlockFrame:
    """A block a step is written in: the block's number (1-based, in the order blocks are
    written), which of its lists holds the step (``steps``, ``rescue`` or ``always``),
    where the block is written and what the operator sees of it."""

    block: int
    part: str
    location: Location
    title: str = "block"

    @property
    def name(self) -> str:
        """E.g. ``block 2 (capture) rescue``."""
        shown = f" ({self.title})" if self.title != "block" else ""
        return f"block {self.block}{shown} {self.part}"


#: The parameter model of a step (``ResolvedStep[MoveParams]``).
P = TypeVar("P", bound=StepParams, covariant=True)


@dataclass(frozen=True, eq=False)
class ResolvedStep(Generic[P]):
    """One step of the flattened sequence (includes expanded).

    ``number`` is 1-based in the flat list; ``location`` is where the step is written;
    ``include_chain`` the include steps that led to it, outermost first.
    """

    number: int
    kind: str
    params: P
    location: Location
    label: str | None = None
    include_chain: tuple[Location, ...] = ()
    document: Document | None = field(default=None, repr=False)
    node: Any = field(default=None, repr=False)  # the parameters' YAML node
    #: What the operator sees of each include in ``include_chain`` (its label, else
    #: "include FILE"), outermost first.
    include_labels: tuple[str, ...] = ()
    #: The kind's one-line description of the step (``StepKind.describe``), e.g. "move to
    #: pose totem": its title when it has no label.
    description: str = ""
    #: The sequence's parameters an expression may read as ``params.NAME``: name ->
    #: (expression type, unit); and the value of every parameter, for the run.
    param_types: Mapping[str, tuple[str, str | None]] = field(default_factory=dict,
                                                               repr=False)
    param_values: Mapping[str, Any] = field(default_factory=dict, repr=False)
    #: The blocks the step is written in, outermost first (empty: none).
    blocks: tuple[BlockFrame, ...] = ()

    def where(self, *path: Any, key: bool = False) -> Location:
        """Location of a parameter, e.g. ``where("joints", "j4")``; without a path, the step's
        own location. Where the path is not written out (shorthand), the nearest enclosing
        value."""
        if not path or self.document is None or self.node is None:
            return self.location
        return self.document.locate(path, start=self.node, key=key)

    def error(self, message: str, *path: Any, key: bool = False) -> SourceError:
        return self.where(*path, key=key).error(message)

    @property
    def title(self) -> str:
        """What the operator sees: the label, or a short description of the step."""
        return self.label or self.description or self.kind


@dataclass(frozen=True, eq=False)
class FrozenPose:
    """A pose file as it was read and validated with a sequence
    (:attr:`seqrun.sequence.loader.LoadedSequence.poses`)."""

    name: str
    pose: Any  # seqrun.arm.poses.PoseFile
    document: Document = field(repr=False)

    @property
    def joints_deg(self) -> dict[str, float]:
        return dict(self.pose.joints_deg)
