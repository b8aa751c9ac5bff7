"""One registry per step kind: every kind has all its parts, the sequence file's union,
the static checks and the executor's handlers all come from the registry, a handler uses
nothing of the executor beyond :class:`seqrun.steps.context.StepContext` and a check
nothing of the validator beyond :class:`seqrun.steps.check_context.CheckContext`."""

from __future__ import annotations

import ast
import importlib
import pkgutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import seqrun.steps
from seqrun import schema
from seqrun.steps.check_context import CheckContext
from seqrun.steps.context import StepContext
from seqrun.steps.registry import HANDLERS
from seqrun.steps.kind import StepKind
from seqrun.steps.params import StepParams
from seqrun.steps.registry import KINDS, step_kind

ROOT = Path(__file__).resolve().parents[1]
STEPS_DIR = Path(seqrun.steps.__file__).parent


def missing_parts(kind: StepKind) -> list[str]:
    """What a step kind lacks (empty: it is complete)."""
    missing = []
    if not (isinstance(kind.params, type) and issubclass(kind.params, StepParams)):
        missing.append("params (a StepParams model)")
    elif kind.params.kind != kind.name or kind.params.yaml_name != kind.name:
        missing.append(f"params.kind/yaml_name = {kind.name!r}")
    elif not kind.params.__doc__:
        missing.append("params docstring (the docs' description of the step)")
    if kind.value is None:
        missing.append("value (the type under the step's key)")
    for part in ("describe", "check", "run", "poses"):
        if not callable(getattr(kind, part)):
            missing.append(part)
    if not kind.bare and not kind.example:
        missing.append("example (a step that needs parameters shows one)")
    return missing


def protocol_members(protocol: type) -> set[str]:
    names = set(getattr(protocol, "__annotations__", {}))
    names |= {n for n, v in vars(protocol).items()
              if (callable(v) or isinstance(v, property)) and not n.startswith("_")}
    return names


CONTEXT_MEMBERS = protocol_members(StepContext)
CHECK_MEMBERS = protocol_members(CheckContext)


# --------------------------------------------------------------------------- completeness
@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_every_registered_kind_has_every_part(kind):
    assert missing_parts(kind) == []
    assert step_kind(kind.name) is kind


def test_a_kind_lacking_a_part_is_caught():
    reset = step_kind("reset")
    broken = StepKind(name="gripper", params=reset.params, value=reset.value,
                      describe=reset.describe, check=reset.check, run=None)  # type: ignore
    assert missing_parts(broken) == ["params.kind/yaml_name = 'gripper'", "run",
                                     "example (a step that needs parameters shows one)"]


def test_every_step_module_with_a_kind_is_registered():
    defined = []
    for info in pkgutil.iter_modules([str(STEPS_DIR)]):
        module = importlib.import_module(f"seqrun.steps.{info.name}")
        if isinstance(getattr(module, "KIND", None), StepKind):
            defined.append(module.KIND)
    assert sorted(k.name for k in defined) == sorted(k.name for k in KINDS)
    assert all(any(k is r for r in KINDS) for k in defined)


# --------------------------------------------------------------------------- agreement
def test_schema_union_and_registry_agree():
    names = [kind.name for kind in KINDS]
    assert list(schema.PARAMS_MODELS) == names + ["include", "block"]
    assert list(schema.STEP_KINDS) == names + ["include", "block"]
    assert set(schema.BARE_STEPS) == {k.name for k in KINDS if k.bare}
    for kind in KINDS:
        assert schema.PARAMS_MODELS[kind.name] is kind.params
        assert schema.STEP_MODELS[kind.name].kind == kind.name
    # the union the files are validated with: one tagged member per kind (+ bare, include,
    # block)
    union = schema.step_adapter().core_schema
    while union.get("type") != "tagged-union":
        union = union["schema"]
    assert set(union["choices"]) == ({f"step:{n}" for n in names}
                                     | {"step:bare", "step:include", "step:block"})
    # and the JSON Schema editors see
    defs = schema.sequence_json_schema()["$defs"]
    for kind in KINDS:
        assert kind.params.__name__ in defs
        assert kind.name in defs[schema.STEP_MODELS[kind.name].__name__]["properties"]


def test_handlers_and_checks_come_from_the_registry():
    assert {name: run for name, run in HANDLERS.items()} == {k.name: k.run for k in KINDS}


def test_each_kind_parses_checks_and_describes_its_own_steps(tmp_path):
    """A step of every kind, written in a file, reaches its kind's parameters and title."""
    from seqrun.sequence.loader import load_sequence

    (tmp_path / "poses").mkdir()
    for pose in (ROOT / "poses").glob("*.yaml"):
        (tmp_path / "poses" / pose.name).write_text(pose.read_text())
    (tmp_path / "sequences").mkdir()
    examples = [kind.name if kind.bare else kind.example for kind in KINDS]
    path = tmp_path / "sequences" / "all.yaml"
    path.write_text("name: every kind\ndescription: one step of each\nsteps:\n"
                    + "".join(f"  - {example}\n" for example in examples))
    loaded = load_sequence(path)
    assert [s.kind for s in loaded.steps] == [k.name for k in KINDS]
    for step, kind in zip(loaded.steps, KINDS):
        assert isinstance(step.params, kind.params)
        assert step.title == kind.describe(step.params)


# --------------------------------------------------------------------------- the context
def _context_uses(tree: ast.Module, protocol: str = "StepContext") -> dict[str, set[str]]:
    """Per function: the attributes read or set on its parameter typed ``protocol``."""
    uses: dict[str, set[str]] = {}
    for node in ast.walk(tree):
        if not isinstance(node, ast.FunctionDef):
            continue
        typed = {a.arg for a in node.args.args + node.args.kwonlyargs
                 if isinstance(a.annotation, ast.Name) and a.annotation.id == protocol}
        if not typed:
            continue
        found = uses.setdefault(node.name, set())
        for inner in ast.walk(node):
            if (isinstance(inner, ast.Attribute) and isinstance(inner.value, ast.Name)
                    and inner.value.id in typed):
                found.add(inner.attr)
            if (isinstance(inner, ast.Call) and isinstance(inner.func, ast.Name)
                    and inner.func.id in ("getattr", "setattr", "hasattr") and inner.args
                    and isinstance(inner.args[0], ast.Name) and inner.args[0].id in typed):
                found.add("<getattr>")  # reaching past the protocol
    return uses


def test_handlers_use_only_the_step_context():
    handlers = 0
    for path in sorted(STEPS_DIR.glob("*.py")):
        for function, used in _context_uses(ast.parse(path.read_text())).items():
            handlers += 1
            assert used <= CONTEXT_MEMBERS, f"{path.name}:{function} uses " \
                                            f"{sorted(used - CONTEXT_MEMBERS)}"
    assert handlers >= len(KINDS)  # every run(step, ex) is typed, so it was looked at


def test_the_checker_catches_a_handler_reaching_past_the_context():
    source = textwrap.dedent("""
        def run(step, ex: StepContext):
            ex.driver.halt(None)
            return {"t": ex._t0, "x": getattr(ex, "last", None)}
    """)
    assert _context_uses(ast.parse(source)) == {"run": {"driver", "_t0", "<getattr>"}}


def test_the_executor_provides_the_step_context():
    from seqrun.clock import VirtualClock
    from seqrun.service.connection import open_connection
    from seqrun.executor import Executor
    from seqrun.sequence.checks import check_from_arm
    from seqrun.powercube.client import PowerCubeClient
    from seqrun.arm.description import load_arm

    arm = load_arm(ROOT / "arms" / "lwa3.yaml")
    clock = VirtualClock()
    connection = open_connection(force_sim=True, clock=clock)
    try:
        client = PowerCubeClient(connection.bus, clock)
        executor = Executor(client, arm, clock, dry_run=True, sequence_check=check_from_arm)
        missing = sorted(m for m in CONTEXT_MEMBERS if not hasattr(executor, m))
        assert missing == []
    finally:
        connection.close()


class _OnlyTheContext:
    """The executor as a handler may see it: anything beyond StepContext raises."""

    def __init__(self, executor) -> None:
        object.__setattr__(self, "_executor", executor)

    def __getattr__(self, name: str):
        if name not in CONTEXT_MEMBERS:
            raise AssertionError(f"a handler used executor.{name}, not in StepContext")
        return getattr(self._executor, name)

    def __setattr__(self, name: str, value) -> None:
        if name not in CONTEXT_MEMBERS:
            raise AssertionError(f"a handler set executor.{name}, not in StepContext")
        setattr(self._executor, name, value)


def test_runs_of_every_kind_use_only_the_step_context(tmp_path, monkeypatch):
    """The real executor on the simulator: each handler gets the executor behind a guard
    that lets through only StepContext's members."""
    from seqrun.arm.description import load_arm
    from seqrun.service.dryrun import dry_run
    from seqrun.sequence.loader import load_sequence

    for kind in KINDS:
        monkeypatch.setitem(HANDLERS, kind.name,
                            lambda step, ex, run=kind.run: run(step, _OnlyTheContext(ex)))
    (tmp_path / "poses").mkdir()
    for pose in (ROOT / "poses").glob("*.yaml"):
        (tmp_path / "poses" / pose.name).write_text(pose.read_text())
    (tmp_path / "sequences").mkdir()
    path = tmp_path / "sequences" / "every.yaml"
    path.write_text(textwrap.dedent("""\
        name: every kind
        description: each step kind once, on the simulator
        steps:
          - reset
          - home: [j1, j2]
          - home
          - set_limits: {max_velocity_deg_s: {j1: 20}}
          - move: totem
          - move: opsafe
          - move: {joints: {j1: 5}, relative: true}
          - wait: {until: in_position}
          - move: {position_mm: [0, 0, -20], relative: true, frame: tool}
          - move_linear: {position_mm: [0, 0, 20], relative: true, frame: tool, speed_mm_s: 20}
          - checkpoint: {moved_mm: [0, 0, 20], frame: tool}
          - move: totem
          - checkpoint: totem
          - confirm: Is the desk clear?
          - wait: 0.1
          - power_off: totem
          - halt: [j1]
    """))
    arm = load_arm(ROOT / "arms" / "lwa3.yaml")
    park = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
    run = dry_run(load_sequence(path), arm, park)
    assert run.result.exit_code == 0, run.result.message
    assert [s.status for s in run.result.steps] == ["passed"] * 17


# --------------------------------------------------------------------------- the checks' context
def _check_uses() -> dict[str, set[str]]:
    """Per step module's function: what it uses of its parameter typed CheckContext."""
    return {f"{path.name}:{function}": used for path in sorted(STEPS_DIR.glob("*.py"))
            for function, used in _context_uses(ast.parse(path.read_text()),
                                                "CheckContext").items()}


def test_checks_use_only_the_check_context():
    uses = _check_uses()
    beyond = {where: sorted(used - CHECK_MEMBERS) for where, used in uses.items()
              if used - CHECK_MEMBERS}
    assert beyond == {}
    checks = {where for where in uses if where.endswith(":check")}
    assert len(checks) == len(KINDS)  # every kind's check(checker, ...) is typed: looked at


def test_the_check_context_lists_exactly_what_the_checks_use():
    """No member for nobody: the protocol says what the kinds need of the validator."""
    used = set().union(*_check_uses().values())
    assert sorted(CHECK_MEMBERS - used) == []


def test_the_checker_catches_a_check_reaching_past_its_context():
    source = textwrap.dedent("""
        def check(checker: CheckContext, step, params):
            checker.loaded.steps
            checker.errors.append(checker._chain)
    """)
    assert _context_uses(ast.parse(source), "CheckContext") == {
        "check": {"loaded", "errors", "_chain"}}


def _checker(tmp_path):
    from seqrun.arm.description import load_arm
    from seqrun.sequence.loader import load_sequence
    from seqrun.sequence.validation import Checker

    path = tmp_path / "one.yaml"
    path.write_text("name: one\ndescription: a step\nsteps:\n  - reset\n")
    arm = load_arm(ROOT / "arms" / "lwa3.yaml")
    return Checker(load_sequence(path), arm, {j.name: 0.0 for j in arm.joints}, started=True)


def test_the_checker_provides_the_check_context(tmp_path):
    checker = _checker(tmp_path)
    assert sorted(m for m in CHECK_MEMBERS if not hasattr(checker, m)) == []


class _OnlyTheCheckContext:
    """The validator as a check may see it: anything beyond CheckContext raises."""

    def __init__(self, checker) -> None:
        object.__setattr__(self, "_checker", checker)

    def __getattr__(self, name: str):
        if name not in CHECK_MEMBERS:
            raise AssertionError(f"a check used checker.{name}, not in CheckContext")
        return getattr(self._checker, name)

    def __setattr__(self, name: str, value) -> None:
        if name not in CHECK_MEMBERS:
            raise AssertionError(f"a check set checker.{name}, not in CheckContext")
        setattr(self._checker, name, value)


def test_checks_of_every_kind_use_only_the_check_context(tmp_path, monkeypatch):
    """The real validation of a sequence with every kind (and its findings): each check
    gets the Checker behind a guard that lets through only CheckContext's members."""
    import dataclasses

    from seqrun.arm.description import load_arm
    from seqrun.sequence import validation
    from seqrun.sequence.loader import load_sequence

    guarded = {kind.name: dataclasses.replace(
        kind, check=lambda checker, step, params, check=kind.check:
        check(_OnlyTheCheckContext(checker), step, params)) for kind in KINDS}
    monkeypatch.setattr(validation, "step_kind", guarded.__getitem__)
    (tmp_path / "poses").mkdir()
    for pose in (ROOT / "poses").glob("*.yaml"):
        (tmp_path / "poses" / pose.name).write_text(pose.read_text())
    (tmp_path / "sequences").mkdir()
    path = tmp_path / "sequences" / "every.yaml"
    path.write_text(textwrap.dedent("""\
        name: every kind
        description: each step kind once, some of them wrong
        steps:
          - reset
          - home: [j1, j2]
          - home
          - set_limits: {max_velocity_deg_s: {j1: 20, j9: 1}}
          - move: totem
          - move: {joints: {j1: 500}, velocity_deg_s: {j1: 999}, timeout_s: 0.01}
          - move: opsafe
          - wait: {until: in_position}
          - move: {position_mm: [0, 0, -20], relative: true, frame: tool}
          - move_linear: {position_mm: [0, 0, 20], relative: true, frame: tool, speed_mm_s: 20}
          - checkpoint: {moved_mm: [0, 0, 20], frame: tool}
          - move: totem
          - checkpoint: opsafe
          - confirm: Is the desk clear?
          - power_off: totem
          - move: {joints: {j1: 1}}
          - halt: [j1, j3]
          - wait: 0.1
    """))
    arm = load_arm(ROOT / "arms" / "lwa3.yaml")
    park = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
    result = validation.validate_sequence(load_sequence(path), arm, park)
    # the wrong steps were checked, through the guard: set_limits (j9), move (target and
    # velocity), checkpoint, move after power_off, halt (locked j3), wait after halt
    assert sorted({error.line for error in result.errors}) == [7, 9, 16, 19, 20, 21]


# --------------------------------------------------------------------------- import weight
def test_the_format_and_the_loader_import_no_maths_and_no_bus():
    """`seqrun validate --static` starts fast: the step kinds' modules import their
    heavy helpers where they run, never when the schema assembles them."""
    code = ("import sys, seqrun.schema, seqrun.sequence.loader, seqrun.steps, seqrun.sequence.checks; "
            "print(' '.join(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout.split()
    assert not {"numpy", "ruckig", "can", "seqrun.executor", "seqrun.sequence.validation"} & set(out)


def test_the_one_step_validator_is_built_only_for_a_file_with_an_invalid_step(project):
    """A valid file is validated by the Sequence model alone; the single-step validator
    (a second copy of the steps' union) is built when a file's steps must be checked one
    by one, and gives the same steps as the whole file's validation would."""
    from seqrun.sequence.loader import load_sequence_partial

    schema.step_adapter.cache_clear()
    loaded, errors = load_sequence_partial(project / "sequences" / "startup.yaml")
    assert not errors and loaded is not None
    assert schema.step_adapter.cache_info().currsize == 0
    text = (project / "sequences" / "startup.yaml").read_text(encoding="utf-8")
    broken = project / "sequences" / "broken.yaml"
    broken.write_text(text + "  - wait: {seconds: -1}\n", encoding="utf-8")
    partial, errors = load_sequence_partial(broken)
    assert errors and schema.step_adapter.cache_info().currsize == 1
    assert [s.kind for s in partial.steps] == [s.kind for s in loaded.steps]
