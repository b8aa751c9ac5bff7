"""Reading a sequence file: includes expanded, every step with its own ``file:line:col``.

:func:`load_sequence` reads a file with its includes into a flat list of
:class:`~seqrun.steps.resolved.ResolvedStep`; the poses the steps name are read once and
frozen with it (:attr:`LoadedSequence.poses`, :class:`~seqrun.steps.resolved.FrozenPose`),
with the SHA-256 of every file read. Both are the step layer's data: the loader builds them,
the step kinds read them. What a file may say is :mod:`seqrun.schema`; what it means for
the arm is :mod:`seqrun.sequence.validation`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from seqrun.errors import SequenceInvalid, SourceError, UserInputError
from seqrun.schema import (
    MAX_INCLUDE_DEPTH,
    MAX_STEPS,
    PARAMS_MODELS,
    BlockParams,
    IncludeParams,
    Sequence,
    describe,
    step_adapter,
)
from seqrun.steps.registry import step_kind
from seqrun.steps.resolved import BlockFrame, FrozenPose, ResolvedStep
from seqrun.yamlsource import Document, Location, display_path, load_document, sort_errors

__all__ = [
    "LoadedSequence",
    "find_project_root",
    "load_sequence",
    "load_sequence_partial",
]


@dataclass(frozen=True, eq=False)
class LoadedSequence:
    """A sequence file with its includes expanded into :attr:`steps`."""

    path: Path
    file: str
    name: str
    description: str
    project_root: Path
    poses_dir: Path
    arm_path: Path
    steps: tuple[ResolvedStep, ...]
    files: tuple[Path, ...] = ()  # every file read, the top one first
    #: Where poses are looked up, first match wins (the campaign's, then the shipped).
    pose_path: tuple[Path, ...] = ()
    #: The campaign or project the sequence belongs to (seqrun.sequence.project.Project).
    project: Any = None
    #: Every pose the steps name, read once at load time: the run uses these, never the
    #: files again (a pose file edited during a run changes nothing).
    poses: Mapping[str, FrozenPose] = field(default_factory=dict)
    #: SHA-256 of every sequence file read (same order as ``files``).
    digests: tuple[str, ...] = ()
    #: The bytes of every sequence file as read and validated (same order as ``files``):
    #: what a run folder keeps, never the files read again.
    sources: tuple[bytes, ...] = field(default=(), repr=False)
    #: The arm these steps run on in a campaign with several arms (its track of the
    #: sequence, seqrun.sequence.arm_tracks); None: the one arm.
    arm_id: str | None = None
    #: Steps left out because they failed on their own (:func:`load_sequence_partial`):
    #: ``(steps kept before it, its kind or None when not even that is known)`` each, so
    #: that validation knows from where the arm's state is uncertain, and how.
    left_out: tuple[tuple[int, str | None], ...] = ()
    #: The parameters the file declares (name -> ParameterSpec) and the value of each
    #: used here (the default or --param), already put into the steps.
    parameters: Mapping[str, Any] = field(default_factory=dict)
    param_values: Mapping[str, Any] = field(default_factory=dict)
    #: The top file's ``monitors:`` (MonitorSpec each), watched during every step, and
    #: where they are written (a ResolvedStep of kind "sequence" for their errors and
    #: their expressions' parameter types); None without any.
    monitors: tuple[Any, ...] = ()
    monitors_at: ResolvedStep | None = None

    @property
    def location(self) -> Location:
        return Location(self.file, 1, 1)

    def split_at(self, first_step: int) -> tuple[LoadedSequence, LoadedSequence]:
        """The steps before ``first_step`` (1-based) and the steps from it on, as two
        sequences (``--from N``: the steps before are only tracked, not run)."""
        return (replace(self, steps=self.steps[:first_step - 1]),
                replace(self, steps=self.steps[first_step - 1:]))

    def inputs(self) -> list[dict[str, str]]:
        """The files this sequence was validated from: ``{kind, file, sha256}`` each, for the
        run folder (the arm file is added by whoever loaded the arm)."""
        items = [{"kind": "sequence", "file": display_path(p), "sha256": d}
                 for p, d in zip(self.files, self.digests)]
        items += [{"kind": "pose", "file": pose.document.file, "sha256": pose.document.sha256}
                  for pose in self.poses.values()]
        return items


@dataclass(frozen=True)
class _TemplateCall:
    """An include's ``with:`` values (name -> typed value, as written) and where its
    parameters are written (for its errors)."""

    values: Mapping[str, Any]
    doc: Document
    node: Any  # the include step's parameters

    def error(self, message: str, *path: Any, key: bool = False) -> SourceError:
        return self.doc.error(("with", *path), message, start=self.node, key=key)


class StepCollector:
    """Collects resolved steps handed to it one file's items at a time, includes expanded
    and poses frozen as :func:`load_sequence` does: each arm of a campaign with several
    arms collects its own track (:mod:`seqrun.sequence.arm_tracks`)."""

    def __init__(self, top: Path, project: Any) -> None:
        self._loader = _Loader(top, project)

    def add(self, doc: Document, path: Path, steps: list, nodes: list) -> None:
        """Validated step models (``step_adapter``) and their YAML nodes, in order."""
        self._loader._steps(doc, path, steps, nodes, (), ())

    def append(self, step: ResolvedStep) -> ResolvedStep:
        """A step made by the caller (a synchronisation step), numbered in this track."""
        step = replace(step, number=len(self._loader.steps) + 1)
        self._loader.steps.append(step)
        return step

    @property
    def steps(self) -> list[ResolvedStep]:
        return self._loader.steps

    @property
    def errors(self) -> list[SourceError]:
        return self._loader.errors

    @property
    def poses(self) -> dict[str, FrozenPose]:
        return self._loader.poses

    @property
    def files(self) -> list[Path]:
        """The included files read (the caller's own file is not among them)."""
        return self._loader.files

    @property
    def digests(self) -> list[str]:
        return self._loader.digests

    @property
    def sources(self) -> list[bytes]:
        return self._loader.sources


def find_project_root(path: str | os.PathLike[str]) -> Path:
    """Nearest ancestor of ``path`` holding an ``arms/`` or ``poses/`` folder; else the cwd."""
    start = Path(path).resolve()
    for folder in (start if start.is_dir() else start.parent, *start.parents):
        if (folder / "arms").is_dir() or (folder / "poses").is_dir():
            return folder
    return Path.cwd().resolve()


class _Loader:
    def __init__(self, top: Path, project: Any, given: Mapping[str, str] | None = None) -> None:
        #: --param NAME=VALUE texts; the declarations, values and expression types.
        self.given: Mapping[str, str] = given or {}
        self.specs: dict[str, Any] = {}
        self.declared: list[str] = []
        self.values: dict[str, Any] = {}
        self.param_types: dict[str, tuple[str, str | None]] = {}
        self.project = project  # seqrun.sequence.project.Project: lookups of poses, arm, includes
        self.root = project.root
        self.poses_dir = project.poses_dir
        self.pose_path = project.pose_path
        self.tree = project.include_tree(top)
        self.errors: list[SourceError] = []
        self.steps: list[ResolvedStep] = []
        self.files: list[Path] = []
        self.arm_path: Path | None = None
        self.pose_problems: dict[str, str | None] = {}
        self.poses: dict[str, FrozenPose] = {}
        self.digests: list[str] = []
        self.sources: list[bytes] = []
        self.include_titles: dict[Location, str] = {}
        #: The blocks around the steps being read, outermost first; blocks read so far.
        self.blocks: tuple[BlockFrame, ...] = ()
        self.block_count = 0
        self.top: Any = None  # the top file's data, when it could be read
        #: Steps left out (see LoadedSequence.left_out).
        self.left_out: list[tuple[int, str | None]] = []
        #: The top file's monitors and where they are written (LoadedSequence.monitors).
        self.monitors: list[Any] = []
        self.monitors_at: ResolvedStep | None = None

    def load(self, path: Path, *, chain: tuple[Path, ...] = (),
             include_chain: tuple[Location, ...] = (), include_step: Any = None,
             call: _TemplateCall | None = None) -> Any:
        try:
            doc = load_document(path, file=display_path(path))
        except SequenceInvalid as exc:
            self.errors.extend(exc.errors)
            if chain:
                self.left_out.append((len(self.steps), None))  # an include's steps
            return None
        except UserInputError as exc:
            if include_step is None:
                raise  # the file named on the command line
            self.errors.append(include_step.error(str(exc)))
            self.left_out.append((len(self.steps), None))
            return None
        self.files.append(path)
        self.digests.append(doc.sha256)
        self.sources.append(doc.source)
        if not chain:
            self.top = doc.data
        # a template (an included file with params of its own) has them for its steps only
        scope = (self.specs, self.declared, self.values, self.param_types)
        try:
            errors = len(self.errors)
            doc = self._parameters(doc, top=not chain, call=call)
            if chain and call is not None and len(self.errors) > errors:
                # the include's with: is wrong: its steps would only repeat it
                self.left_out.append((len(self.steps), None))
                return None
            try:
                seq = doc.validate(Sequence, context={"params": self.param_types})
            except SequenceInvalid as exc:
                # Report every problem at once: go on with the steps that are valid on
                # their own (their includes and poses are checked too); the file's errors
                # are known.
                self.errors.extend(exc.errors)
                self._partial(doc, path, chain, include_chain)
                return None
            self._check_arm(doc, seq, top=not chain)
            self._monitors(doc, seq, top=not chain)
            self._steps(doc, path, seq.steps, doc.items(doc.child(doc.root, "steps")), chain,
                        include_chain)
            return seq
        finally:
            if chain:
                self.specs, self.declared, self.values, self.param_types = scope

    def _monitors(self, doc: Document, seq: Any, *, top: bool) -> None:
        """The top file's ``monitors:``; an included file may declare none (its steps are
        watched by the including sequence's)."""
        if not seq.monitors:
            return
        if not top:
            self.errors.append(doc.error(("monitors",), "an included file cannot declare "
                                                        "monitors: the including sequence's "
                                                        "watch its steps", key=True))
            return
        self.monitors = list(seq.monitors)
        self.monitors_at = ResolvedStep(0, "sequence", seq, doc.locate(("monitors",)),
                                        label="the sequence's monitors", document=doc,
                                        node=doc.root, param_types=dict(self.param_types),
                                        param_values=dict(self.values))

    def _template(self, doc: Document, declared: dict, call: _TemplateCall | None) -> None:
        """An included file's own ``params:``: their values from the include's ``with:``
        (typed as written, each checked against its declaration) over the defaults."""
        from seqrun.steps.sequence_parameters import (
            NAME_RE,
            ParameterSpec,
            expression_types,
            value_problem,
        )

        names = [n for n in declared if isinstance(n, str)]
        specs: dict[str, Any] = {}
        for name in names:
            try:
                if NAME_RE.match(name):
                    specs[name] = ParameterSpec.model_validate(declared[name])
            except ValidationError:
                pass  # reported with the file's errors
        given = dict(call.values) if call is not None else {}
        values: dict[str, Any] = {}
        for name, value in given.items():
            if name not in specs:
                assert call is not None
                self.errors.append(call.error(
                    f"{doc.file} declares no parameter '{name}' (declared: "
                    f"{', '.join(names) or 'none'})", name, key=True))
        for name, spec in specs.items():
            if name in given:
                problem = value_problem(spec, given[name])
                if problem is None:
                    values[name] = float(given[name]) if spec.type == "float" else given[name]
                    continue
                assert call is not None
                self.errors.append(call.error(f"with {name}: {problem}", name))
            elif spec.default is None:
                where = call.error if call is not None else None
                message = (f"parameter '{name}' of {doc.file} has no default: give it with "
                           f"'with: {{{name}: VALUE}}'")
                self.errors.append(where(message, key=True) if where is not None
                                   else doc.error(("params", name), message, key=True))
            if name not in values and spec.default is not None:
                values[name] = float(spec.default) if spec.type == "float" else spec.default
        self.specs, self.declared, self.values = specs, names, values
        self.param_types = expression_types(specs)

    def _parameters(self, doc: Document, *, top: bool,
                    call: _TemplateCall | None = None) -> Document:
        """``doc`` with the parameters' values put into its steps: the top file's
        declarations (an included file uses them too), or an included file's own (a
        template: the values its include gives ``with:``). Raises UserInputError for a bad
        or missing value (--param)."""
        from seqrun.steps.sequence_parameters import (
            NAME_RE,
            ParameterSpec,
            expression_types,
            resolve_values,
            substitute,
        )

        data = doc.data
        if not isinstance(data, dict):
            return doc
        declared = data.get("params")
        if top:
            given_specs = declared if isinstance(declared, dict) else {}
            names = [n for n in given_specs if isinstance(n, str)]
            for name in self.given:
                if name not in names:
                    raise UserInputError(f"--param {name}: {doc.file} declares no parameter "
                                         f"'{name}' (declared: {', '.join(names) or 'none'})")
            for name in names:
                try:
                    if NAME_RE.match(name):
                        self.specs[name] = ParameterSpec.model_validate(given_specs[name])
                except ValidationError:
                    pass  # reported with the whole file's errors
            self.declared = names
            self.values = resolve_values(
                self.specs, {n: t for n, t in self.given.items() if n in self.specs},
                file=doc.file)
            self.param_types = expression_types(self.specs)
        elif isinstance(declared, dict):
            self._template(doc, declared, call)
        elif call is not None and call.values:
            self.errors.append(call.error(f"{doc.file} declares no params: 'with' gives "
                                          "values to a template's (an included file's own "
                                          "params:)", key=True))
        steps = data.get("steps")
        if steps is None:
            return doc
        new, errors = substitute(steps, self.values, self.declared,
                                 lambda path, offset: _text_location(doc, path, offset),
                                 ("steps",))
        self.errors.extend(errors)
        if new == steps and not errors:
            return doc
        return replace(doc, data={**data, "steps": new})

    def _partial(self, doc: Document, path: Path, chain: tuple[Path, ...],
                 include_chain: tuple[Location, ...]) -> None:
        if not chain:
            self.arm_path = self._arm(None)
        data = doc.data.get("steps") if isinstance(doc.data, dict) else None
        if not isinstance(data, list):
            return
        good: list[Any] = []
        nodes = []
        for item, node in zip(data, doc.items(doc.child(doc.root, "steps"))):
            try:
                good.append(step_adapter().validate_python(
                    item, context={"params": self.param_types}))
            except ValidationError:
                # already reported by the whole-file validation; validation goes on past
                # it, knowing what kind of step is missing
                good.append(_LeftOut(_written_kind(item)))
            nodes.append(node)
        self._steps(doc, path, good, nodes, chain, include_chain)

    def _steps(self, doc: Document, path: Path, steps: list, items: list,
               chain: tuple[Path, ...], include_chain: tuple[Location, ...]) -> None:
        for raw, node in zip(steps, items):
            if len(self.steps) >= MAX_STEPS:
                self.errors.append(doc.location(node).error(
                    f"the sequence expands to more than {MAX_STEPS} steps with its includes"))
                return
            if isinstance(raw, _LeftOut):
                self.left_out.append((len(self.steps), raw.kind))
                continue
            if isinstance(raw, str):
                kind, params, params_node = raw, PARAMS_MODELS[raw](), node
            else:
                kind = raw.kind
                params, params_node = raw.params(), doc.child(node, kind)
            here = doc.location(node)
            if isinstance(params, BlockParams):
                self._block(doc, path, params, params_node, here, chain, include_chain)
                continue
            if isinstance(params, IncludeParams):
                self.include_titles[here] = params.label or describe(kind, params)
                self._include(doc, path, params, params_node, here, chain + (path,),
                              include_chain)
                continue
            step_type = step_kind(kind)
            step = ResolvedStep(number=len(self.steps) + 1, kind=kind, params=params,
                                location=here, label=params.label, include_chain=include_chain,
                                document=doc, node=params_node,
                                include_labels=tuple(self.include_titles.get(loc, "include")
                                                     for loc in include_chain),
                                description=step_type.describe(params),
                                param_types=self.param_types, param_values=self.values,
                                blocks=self.blocks)
            for pose in step_type.poses(params):
                self._check_pose(step, pose)
            self.steps.append(step)

    def _block(self, doc: Document, path: Path, params: BlockParams, node: Any,
               here: Location, chain: tuple[Path, ...],
               include_chain: tuple[Location, ...]) -> None:
        """A block's steps, rescue and always, each step knowing the blocks it is in."""
        self.block_count += 1
        number, outer = self.block_count, self.blocks
        for part in ("steps", "rescue", "always"):
            steps = getattr(params, part)
            if not steps:
                continue
            self.blocks = outer + (BlockFrame(number, part, here, params.label or "block"),)
            try:
                self._steps(doc, path, steps, list(doc.items(doc.child(node, part))), chain,
                            include_chain)
            finally:
                self.blocks = outer

    def _check_arm(self, doc: Document, seq: Sequence, *, top: bool) -> None:
        if top:
            if seq.arm is None:  # the campaign's arm: not found is bad input, one line
                self.arm_path = self.project.arm_path(None)
                return
            try:
                self.arm_path = self.project.arm_path(seq.arm)
            except UserInputError:
                self.arm_path = self._arm(None)
                looked = ", ".join(str(p) for p in self.project.arm_candidates(seq.arm))
                self.errors.append(doc.error(("arm",), f"arm file '{seq.arm}' not found "
                                                      f"(looked for {looked})"))
            return
        if seq.arm is not None and self._arm(seq.arm) != self.arm_path:
            self.errors.append(doc.error(("arm",), f"this file names arm '{seq.arm}' but the "
                                                  "sequence including it runs on "
                                                  f"{self.arm_path}; remove 'arm' here or "
                                                  "make it the same"))

    def _arm(self, name: str | None) -> Path:
        """The arm file ``name`` means (the first candidate when none exists: the run
        then says it is missing)."""
        try:
            return self.project.arm_path(name)
        except UserInputError:
            return self.project.arm_candidates(name)[0].resolve()

    def _include(self, doc: Document, path: Path, params: IncludeParams, node: Any,
                 here: Location, chain: tuple[Path, ...],
                 include_chain: tuple[Location, ...]) -> None:
        def error(message: str) -> None:
            self.errors.append(doc.error(("file",), message, start=node))
            self.left_out.append((len(self.steps), None))  # the included steps

        try:
            target = (path.parent / params.file).resolve()
        except (OSError, RuntimeError, ValueError) as exc:  # symlink loop, NUL byte, ...
            shown = params.file if params.file.isprintable() else ascii(params.file)[1:-1]
            error(f"include '{shown}': cannot resolve the path ({exc})")
            return
        if not target.is_relative_to(self.tree):
            what = "campaign folder" if self.project.is_campaign else "sequences folder"
            error(f"include '{params.file}' is outside the {what} "
                  f"{display_path(self.tree)}; included files must stay inside it")
            return
        if target in chain:
            names = " -> ".join(p.name for p in (*chain[chain.index(target):], target))
            error(f"include loop: {names}")
            return
        if len(chain) >= MAX_INCLUDE_DEPTH:
            error(f"includes nested more than {MAX_INCLUDE_DEPTH} deep")
            return
        try:
            is_file = target.is_file()
        except OSError as exc:  # name too long, permission denied, ...
            error(f"include '{params.file}': cannot use the path ({exc.strerror or exc})")
            return
        if not is_file:
            error(f"include '{params.file}': no such file ({target})")
            return
        self.load(target, chain=chain, include_chain=include_chain + (here,),
                  include_step=doc.locate(("file",), start=node),
                  call=_TemplateCall(params.with_, doc, node))

    def _check_pose(self, step: ResolvedStep, name: str) -> None:
        from seqrun.arm.poses import PoseFile, find_pose

        if name not in self.pose_problems:
            problem = None
            try:
                document = load_document(find_pose(name, self.pose_path))
                self.poses[name] = FrozenPose(name, document.validate(PoseFile), document)
            except UserInputError as exc:
                problem = str(exc)
            except SequenceInvalid as exc:
                self.errors.extend(exc.errors)
                problem = f"pose '{name}' cannot be used: its file has errors"
            self.pose_problems[name] = problem
        known = self.pose_problems[name]
        if known is not None:
            self.errors.append(step.error(known, "pose"))


def load_sequence(path: str | os.PathLike[str], *,
                  project_root: str | os.PathLike[str] | None = None,
                  params: Mapping[str, str] | None = None) -> LoadedSequence:
    """Read a sequence file with its includes; every step keeps its own ``file:line:col``.

    Poses come from ``<project root>/poses/``, then the shipped poses; the project is the
    nearest campaign (``seqrun.toml``) above the file, or ``project_root`` (``--project``),
    else the nearest folder with ``arms/`` or ``poses/`` (see :mod:`seqrun.sequence.project`); an
    unknown pose is a located error listing the available ones. ``params``: the
    ``--param NAME=VALUE`` texts over the declared defaults. Raises
    :class:`SequenceInvalid` with every error found, :class:`UserInputError` if the file
    cannot be read.
    """
    loaded, errors = load_sequence_partial(path, project_root=project_root, params=params)
    if errors:
        raise SequenceInvalid(errors)
    assert loaded is not None
    return loaded


def load_sequence_partial(path: str | os.PathLike[str], *,
                          project_root: str | os.PathLike[str] | None = None,
                          params: Mapping[str, str] | None = None
                          ) -> tuple[LoadedSequence | None, list[SourceError]]:
    """:func:`load_sequence` that keeps going: ``(loaded, errors)``, where ``loaded`` holds
    the steps that are valid on their own (a step that fails its schema is left out) so
    that the checks against the arm can still report on them; None if nothing of the top
    file could be read. Raises :class:`UserInputError` if the file cannot be read."""
    from seqrun.sequence.project import project_for

    path = Path(path)
    try:
        top = path.resolve()
        project = project_for(top, Path(project_root) if project_root is not None else None)
    except (OSError, RuntimeError, ValueError) as exc:  # symlink loop, NUL byte, ...
        raise UserInputError(f"{path}: cannot resolve the path ({exc})") from None
    root = project.root
    loader = _Loader(top, project, params)
    seq = loader.load(top)
    errors = sort_errors(loader.errors)
    if seq is not None:
        name, description = seq.name, seq.description
    elif isinstance(loader.top, dict):
        name = loader.top.get("name") if isinstance(loader.top.get("name"), str) else top.stem
        description = loader.top.get("description")
        description = description if isinstance(description, str) else ""
    else:
        return None, errors
    assert loader.arm_path is not None
    return LoadedSequence(path=path, file=display_path(path), name=name or top.stem,
                          description=description, project_root=root,
                          poses_dir=loader.poses_dir, arm_path=loader.arm_path,
                          steps=tuple(loader.steps), files=tuple(loader.files),
                          pose_path=tuple(loader.pose_path), project=project,
                          poses=dict(loader.poses), digests=tuple(loader.digests),
                          sources=tuple(loader.sources),
                          left_out=tuple(loader.left_out),
                          parameters=dict(loader.specs),
                          param_values=dict(loader.values),
                          monitors=tuple(loader.monitors),
                          monitors_at=loader.monitors_at), errors


def _text_location(doc: Document, path: tuple, offset: int) -> Location:
    """Where the character ``offset`` of the text at ``path`` stands: exact for a text on
    one line written plain or in quotes without escapes, else the text's start."""
    from yaml.nodes import ScalarNode

    node = doc.find(path)
    here = doc.location(node)
    if isinstance(node, ScalarNode) and "\n" not in node.value and "\\" not in node.value \
            and node.style in (None, "'", '"') and "''" not in node.value:
        quote = 0 if node.style is None else 1
        return Location(here.file, here.line, here.column + quote + offset)
    return here


@dataclass(frozen=True)
class _LeftOut:
    """A step that failed its schema, where it stood among the steps."""

    kind: str | None


def _written_kind(item: Any) -> str | None:
    """The step kind a step that failed its schema was written as (None: not even that)."""
    name = item if isinstance(item, str) else (
        next(iter(item)) if isinstance(item, dict) and len(item) == 1 else None)
    # an include brings steps of any kind: unknown
    return name if isinstance(name, str) and name in PARAMS_MODELS \
        and name not in ("include", "block") \
        else None


