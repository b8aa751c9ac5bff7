"""A sequence of a campaign with several arms, split into one track per arm.

In a campaign whose ``seqrun.toml`` names arms (``[arms.A]``, ``[arms.B]``) a sequence's
steps name their arm, and a ``parallel:`` block runs branches on different arms at the
same time (docs/two-arms.md)::

    steps:
      - include: {file: startup.yaml, arm: A}
      - move: {pose: hold, arm: A}           # or: - {arm: A, move: hold}
      - parallel:
          - arm: A
            steps:
              - signal: A_holding
              - wait: 5
          - arm: B
            steps:
              - wait_for: {event: A_holding, timeout_s: 30}
              - move_linear: {position_mm: [0, 0, -100], relative: true, frame: tool}
      - move: {pose: opsafe, arm: B}

The steps run in the order written: a step on one arm starts when the step before it (on
whichever arm) has ended, and a parallel block's branches start together and join when
all have ended. :func:`load_tracks` writes that order into each arm's track as ``signal``
and ``wait_for`` steps of its own (their events start with ``~``, which a file cannot
name), so that every arm runs an ordinary sequence on its own executor, and the run and
the checks see the waits. A campaign with one arm needs no ``arm:``; a ``confirm`` without
one is asked by the first arm's run while the others wait. A step naming an arm
the campaign does not have, a step without an arm when there are several, two branches on
one arm: each one line at ``file:line:col``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from seqrun.errors import SequenceInvalid, SourceError, UserInputError
from seqrun.schema import step_adapter
from seqrun.sequence.loader import LoadedSequence, StepCollector
from seqrun.steps.resolved import ResolvedStep
from seqrun.steps.signal import SignalParams
from seqrun.steps.wait_for import WaitForParams
from seqrun.yamlsource import Document, Location, display_path, load_document, sort_errors

__all__ = ["ArmTracks", "load_tracks", "ORDER_PREFIX"]

#: Events the campaign's order adds start with this (a file cannot name one).
ORDER_PREFIX = "~"

_TOP_KEYS = ("name", "description", "steps")


@dataclass
class ArmTracks:
    """A campaign sequence split per arm: ``tracks[arm_id]`` is what that arm runs."""

    path: Path
    file: str
    name: str
    description: str
    project: Any
    tracks: dict[str, LoadedSequence] = field(default_factory=dict)
    errors: list[SourceError] = field(default_factory=list)

    @property
    def arm_ids(self) -> tuple[str, ...]:
        return tuple(self.tracks)

    @property
    def location(self) -> Location:
        return Location(self.file, 1, 1)


class _Tracks:
    def __init__(self, top: Path, project: Any, doc: Document, arm_ids: tuple[str, ...],
                 arm_paths: dict[str, Path]) -> None:
        self.top, self.project, self.doc = top, project, doc
        self.arm_ids = arm_ids
        self.arm_paths = arm_paths
        self.collectors = {a: StepCollector(top, project) for a in arm_ids}
        self.errors: list[SourceError] = []
        self.used: list[str] = []  # the arms that have steps, in order of appearance
        #: The order so far: the events each arm must wait for before the next item.
        self.previous: list[tuple[str, str]] = []  # (arm, event) that ended the last item
        self.items = 0

    # -- a step item and its arm
    def split(self, item: Any, node: Any) -> tuple[str | None, Any, Any, Any]:
        """``(arm, step without arm, arm node, step node)`` of a step item."""
        if isinstance(item, dict) and "arm" in item and len(item) == 2:
            arm_node = self.doc.child(node, "arm")
            rest = {k: v for k, v in item.items() if k != "arm"}
            return self._arm(item["arm"], arm_node), rest, arm_node, node
        if isinstance(item, dict) and len(item) == 1:
            key = next(iter(item))
            value = item[key]
            if isinstance(value, dict) and "arm" in value:
                params_node = self.doc.child(node, key)
                arm_node = self.doc.child(params_node, "arm")
                rest = {key: {k: v for k, v in value.items() if k != "arm"}}
                return self._arm(value["arm"], arm_node), rest, arm_node, node
        return None, item, None, node

    def _arm(self, value: Any, node: Any) -> str | None:
        if not isinstance(value, str) or value not in self.arm_ids:
            shown = value if isinstance(value, str) else repr(value)
            self.errors.append(self.doc.location(node).error(
                f"unknown arm '{shown}' (this campaign has arms {', '.join(self.arm_ids)})"))
            return None
        return value

    def _use(self, arm: str) -> None:
        if arm not in self.used:
            self.used.append(arm)

    # -- the steps of one arm
    def add_steps(self, arm: str, items: list[tuple[Any, Any]]) -> None:
        """Validate step items (already without ``arm``) and hand them to the arm's track."""
        good, nodes = [], []
        for item, node in items:
            if isinstance(item, dict) and "parallel" in item:
                self.errors.append(self.doc.location(node).error(
                    "a parallel block cannot be nested in a branch"))
                continue
            try:
                good.append(step_adapter().validate_python(item))
                nodes.append(node)
            except ValidationError as exc:
                self.errors.extend(self.doc.validation_errors(exc, start=node))
        self.collectors[arm].add(self.doc, self.top, good, nodes)

    def sync(self, arm: str, item_node: Any, what: str) -> None:
        """The campaign's order on ``arm``: wait for the arms that ended the item before."""
        here = self.doc.location(item_node)
        for other, event in self.previous:
            if other == arm:
                continue  # its own steps come in order
            # no timeout of its own (None): the other arm's step is bounded by its own
            params = WaitForParams.model_construct(
                event=event, timeout_s=None,  # type: ignore[arg-type]
                label=f"wait for arm {other}: {what}")
            self.collectors[arm].append(ResolvedStep(
                number=0, kind="wait_for", params=params, location=here,
                label=params.label, document=self.doc, node=item_node,
                description=f"wait for arm {other}"))

    def end(self, arm: str, item_node: Any) -> tuple[str, str]:
        event = f"{ORDER_PREFIX}{self.items}.{arm}"
        params = SignalParams.model_construct(event=event, label=None)
        self.collectors[arm].append(ResolvedStep(
            number=0, kind="signal", params=params, location=self.doc.location(item_node),
            label=f"done (item {self.items})", document=self.doc, node=item_node,
            description=f"signal {event}"))
        return arm, event

    # -- the items of the top list
    def item(self, raw: Any, node: Any, index: int) -> None:
        self.items = index + 1
        if isinstance(raw, dict) and "parallel" in raw:
            self.parallel(raw, node)
            return
        arm, step, _, _ = self.split(raw, node)
        if arm is None:
            if _named_arm(raw):
                return  # an unknown arm: said
            if len(self.arm_ids) > 1 and not _campaign_wide(raw):
                self.errors.append(self.doc.location(node).error(
                    f"which arm? this campaign has arms {', '.join(self.arm_ids)}: name it "
                    "in the step (e.g. '- move: {pose: totem, arm: "
                    f"{self.arm_ids[0]}}}')"))
                return
            arm = self.arm_ids[0]
        self._use(arm)
        what = _item_title(raw)
        self.sync(arm, node, what)
        self.add_steps(arm, [(step, node)])
        self.previous = [self.end(arm, node)]

    def parallel(self, raw: dict, node: Any) -> None:
        body_node = self.doc.child(node, "parallel")
        branches = raw.get("parallel")
        if len(raw) != 1 or not isinstance(branches, list) or len(branches) < 1:
            self.errors.append(self.doc.location(node).error(
                "a parallel block is '- parallel:' with a list of branches, each "
                "'{arm: A, steps: [...]}'"))
            return
        seen: dict[str, Any] = {}
        ended: list[tuple[str, str]] = []
        for branch, branch_node in zip(branches, self.doc.items(body_node)):
            if not isinstance(branch, dict) or set(branch) - {"arm", "steps", "label"} \
                    or "arm" not in branch or not isinstance(branch.get("steps"), list) \
                    or not branch["steps"]:
                self.errors.append(self.doc.location(branch_node).error(
                    "a branch is a mapping '{arm: A, steps: [...]}' (optional label) with "
                    "at least one step"))
                continue
            arm_node = self.doc.child(branch_node, "arm")
            arm = self._arm(branch["arm"], arm_node)
            if arm is None:
                continue
            if arm in seen:
                self.errors.append(self.doc.location(arm_node).error(
                    f"two branches on arm {arm} (the other at line "
                    f"{self.doc.location(seen[arm]).line}): one arm runs one branch at a "
                    "time; put its steps in one branch"))
                continue
            seen[arm] = arm_node
            self._use(arm)
            items = []
            for step_raw, step_node in zip(branch["steps"],
                                           self.doc.items(self.doc.child(branch_node, "steps"))):
                step_arm, step, a_node, _ = self.split(step_raw, step_node)
                if _named_arm(step_raw) and step_arm is None:
                    continue  # unknown: said
                if step_arm is not None and step_arm != arm:
                    self.errors.append(self.doc.location(a_node).error(
                        f"this step names arm {step_arm} inside the branch of arm {arm}; "
                        "a branch's steps run on its arm"))
                    continue
                items.append((step, step_node))
            self.sync(arm, branch_node, "before the parallel block")
            self.add_steps(arm, items)
            ended.append(self.end(arm, branch_node))
        if ended:
            self.previous = ended


def _campaign_wide(raw: Any) -> bool:
    """A step that needs no arm: ``confirm`` (asked once, by the first arm's run, while
    the others wait in the order written)."""
    return isinstance(raw, dict) and set(raw) == {"confirm"}


def _named_arm(raw: Any) -> bool:
    if not isinstance(raw, dict):
        return False
    if "arm" in raw:
        return True
    return len(raw) == 1 and isinstance(next(iter(raw.values())), dict) \
        and "arm" in next(iter(raw.values()))


def _item_title(raw: Any) -> str:
    if isinstance(raw, str):
        return raw
    if isinstance(raw, dict):
        keys = [k for k in raw if k != "arm"]
        if keys:
            value = raw[keys[0]]
            if isinstance(value, dict) and value.get("label"):
                return str(value["label"])
            return str(keys[0]) + (f" {value}" if isinstance(value, (str, int, float)) else "")
    return "the step before"


def load_tracks(path: str | os.PathLike[str], *, project: Any,
                arm_paths: dict[str, Path]) -> ArmTracks:
    """Read a campaign sequence into one track per arm (see the module doc).

    ``arm_paths``: each arm's arm file (its context's). Raises :class:`SequenceInvalid`
    with every error found; :class:`UserInputError` if the file cannot be read."""
    path = Path(path)
    top = path.resolve()
    doc = load_document(top, file=display_path(path))
    arm_ids = tuple(arm_paths)
    errors: list[SourceError] = []
    data = doc.data
    if not isinstance(data, dict):
        raise SequenceInvalid([Location(doc.file, 1, 1).error(
            "a sequence is a mapping with name, description and steps")])
    for key in data:
        if key not in _TOP_KEYS:
            hint = (" (each step names its arm; the arms are in seqrun.toml)"
                    if key == "arm" else "")
            errors.append(doc.error((key,), f"unknown key '{key}' (expected: "
                                            f"{', '.join(_TOP_KEYS)}){hint}", key=True))
    name, description = data.get("name"), data.get("description", "")
    if not isinstance(name, str) or not name:
        errors.append(doc.error(("name",), "name: a non-empty text is required"))
        name = top.stem
    if not isinstance(description, str):
        errors.append(doc.error(("description",), "description: a text"))
        description = ""
    steps = data.get("steps")
    if not isinstance(steps, list) or not steps:
        errors.append(doc.error(("steps",), "steps: a list of at least one step"))
        raise SequenceInvalid(sort_errors(errors))
    builder = _Tracks(top, project, doc, arm_ids, arm_paths)
    for index, (raw, node) in enumerate(zip(steps, doc.items(doc.child(doc.root, "steps")))):
        builder.item(raw, node, index)
    errors += builder.errors
    tracks: dict[str, LoadedSequence] = {}
    for arm in builder.used:
        collector = builder.collectors[arm]
        errors += collector.errors
        tracks[arm] = LoadedSequence(
            path=path, file=doc.file, name=f"{name} (arm {arm})", description=description,
            project_root=project.root, poses_dir=project.poses_dir, arm_path=arm_paths[arm],
            steps=tuple(collector.steps), files=(top, *collector.files),
            pose_path=tuple(project.pose_path), project=project, poses=dict(collector.poses),
            digests=(doc.sha256, *collector.digests),
            sources=(doc.source, *collector.sources), arm_id=arm)
    if errors:
        raise SequenceInvalid(sort_errors(list(dict.fromkeys(errors))))
    if not tracks:
        raise UserInputError(f"{doc.file}: no steps")
    return ArmTracks(path, doc.file, name, description, project, tracks)
