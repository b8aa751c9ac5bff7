"""The layer order of docs/architecture.md holds for the code as built.

The table there is the source: every module of seqrun/ is in exactly one layer, imports
(at the top of a module, inside a function, or for the type checker only) go to the same
layer or an earlier one and never round a circle, and the faces reach the arm only through
the service layer.
"""

from __future__ import annotations

import ast
import fnmatch
import re
from pathlib import Path

import pytest
from projecttree import ROOT, tool

DOC = ROOT / "docs" / "architecture.md"
PACKAGE = ROOT / "seqrun"
#: What a face must not import: it goes through seqrun.service and seqrun.events.
FORBIDDEN_FOR_FACES = ("executor", "drivers", "drivers.*", "powercube", "powercube.*")
FACES = ("cli", "cli.*", "console", "console.*", "foxglove", "foxglove.*", "ros", "ros.*")


#: The import reader of the layer picture: the picture and these checks read one graph.
_reader = tool("draw_layers")
documented_layers = _reader.layer_table
module_name = _reader.module_name


def imported_modules(path: Path, name: str, *, type_only: bool = False) -> set[str]:
    """Every module ``path`` imports anywhere in its code, outside ``if TYPE_CHECKING``;
    ``type_only``: those inside it too (an import for the type checker is an arrow of the
    design as much as any other: a circle through one is still a circle)."""
    return _reader.imports_of(path, name, type_checking=type_only)


def short(module: str) -> str:
    return "seqrun" if module == "seqrun" else module.removeprefix("seqrun.")


def matches(module: str, patterns) -> bool:
    return any(fnmatch.fnmatchcase(short(module), p) for p in patterns)


LAYERS = documented_layers(DOC.read_text(encoding="utf-8"))
MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def layer_of(module: str) -> list[int]:
    return [i for i, (_, patterns) in enumerate(LAYERS) if matches(module, patterns)]


def seqrun_imports(module: str, *, type_only: bool = False) -> set[str]:
    """The seqrun modules ``module`` imports (``type_only``: with those for the type checker)."""
    found = imported_modules(MODULES[module], module, type_only=type_only)
    return {m for m in found if m in MODULES} - {module}


def upward_imports(*, type_only: bool) -> set[tuple[str, str]]:
    """(module, what it imports) where the import goes to a later layer of the table."""
    upward = set()
    for module in sorted(MODULES):
        (own,) = layer_of(module) or (None,)
        if own is None:
            continue
        for target in seqrun_imports(module, type_only=type_only):
            (theirs,) = layer_of(target) or (None,)
            if theirs is not None and theirs > own:
                upward.add((short(module), short(target)))
    return upward


def test_the_table_is_found_and_names_the_faces_last():
    names = [name for name, _ in LAYERS]
    assert len(names) >= 5 and names[-1] == "faces" and "service" in names


@pytest.mark.parametrize("module", sorted(MODULES))
def test_every_module_is_in_exactly_one_layer(module):
    assert len(layer_of(module)) == 1, (
        f"{module} is in {len(layer_of(module))} layers of docs/architecture.md's table")


def test_imports_go_to_the_same_layer_or_an_earlier_one():
    assert sorted(upward_imports(type_only=False)) == []


def test_imports_for_the_type_checker_go_the_same_way():
    assert sorted(upward_imports(type_only=True)) == []


#: The layers a face may import (issue 25.4): the service layer, the events and the other
#: base modules (errors, exit codes, formatting), and the faces themselves.
FACE_LAYERS = ("base", "service", "faces")


def test_faces_import_the_service_layer_and_events_only():
    """Validation, kinematics, poses, the campaign and the simulator are service calls for
    a face (seqrun/service/checking.py, kinematics.py, poses.py, campaigns.py,
    simulator.py), not modules it reaches into; type-only imports do not count."""
    allowed = {i for i, (name, _) in enumerate(LAYERS) if name in FACE_LAYERS}
    reaching = sorted(f"{short(m)} imports {short(t)} ({LAYERS[layer_of(t)[0]][0]})"
                      for m in MODULES if matches(m, FACES)
                      for t in seqrun_imports(m) if layer_of(t) and layer_of(t)[0] not in allowed)
    assert reaching == []


def test_faces_reach_the_arm_only_through_the_service_layer():
    reaching_in = sorted(f"{short(m)} imports {short(t)}" for m in MODULES if matches(m, FACES)
                         for t in seqrun_imports(m) if matches(t, FORBIDDEN_FOR_FACES))
    assert reaching_in == []


POWERCUBE = ("powercube", "powercube.*")
WIRE = POWERCUBE + ("sim", "sim.*")
#: The modules besides the wire layer that may speak PowerCube: the PowerCube driver family,
#: nothing else (issue 25.1). The service layer, the report and every face ask the arm's
#: driver (seqrun/drivers/registry.py): units, offsets, state codes, requests, the watch for
#: another master and the confirmed Halt stay behind it.
POWERCUBE_SPEAKERS = ("drivers.powercube", "drivers.powercube.*")


def test_powercube_is_spoken_only_behind_the_driver_seam():
    speakers = {short(m) for m in MODULES if not matches(m, WIRE)
                and any(matches(t, POWERCUBE) for t in seqrun_imports(m))}
    assert sorted(s for s in speakers if not matches("seqrun." + s, POWERCUBE_SPEAKERS)) == []


def powercube_paths(module: str) -> list[str]:
    """Import chains from ``module`` to seqrun.powercube that pass only through modules of
    the base and the arm-and-format layers (the drivers and the service may speak it)."""
    names = [name for name, _ in LAYERS]
    through = {names.index(name) for name in ("base", "arm", "step kinds", "sequence format")}
    found, seen = [], set()
    stack = [(module, (short(module),))]
    while stack:
        current, path = stack.pop()
        for target in sorted(seqrun_imports(current)):
            if matches(target, POWERCUBE):
                found.append(" -> ".join(path + (short(target),)))
            elif target not in seen and set(layer_of(target)) & through:
                seen.add(target)
                stack.append((target, path + (short(target),)))
    return found


@pytest.mark.parametrize("module", sorted(m for m in MODULES if matches(
    m, ("executor", "execution", "execution.*") + FACES)))
def test_the_executor_and_the_faces_do_not_reach_powercube(module):
    """Not even through a helper of the format layer (telemetry decoded state bytes and
    usermessages described requests there once)."""
    assert powercube_paths(module) == []


def test_the_checker_sees_an_upward_import(tmp_path):
    """The import reader finds imports inside functions and skips type-checking ones."""
    source = tmp_path / "probe.py"
    source.write_text("from typing import TYPE_CHECKING\n"
                      "if TYPE_CHECKING:\n    from seqrun.executor import Executor\n"
                      "def f():\n    from seqrun.powercube import codec\n"
                      "    from . import sibling\n", encoding="utf-8")
    found = imported_modules(source, "seqrun.cli.probe")
    assert "seqrun.powercube.codec" in found and "seqrun.cli.sibling" in found
    assert "seqrun.executor" not in found
    assert "seqrun.executor" in imported_modules(source, "seqrun.cli.probe", type_only=True)


#: Names under which a module holds an executor (or a step's view of it).
EXECUTOR_NAMES = {"executor", "ex", "run"}


def private_uses(path: Path) -> list[str]:
    """Private names (one leading underscore) ``path`` takes from another seqrun module, and
    private attributes it reads of an executor held under a name of :data:`EXECUTOR_NAMES`."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and (node.level or
                                                 (node.module or "").startswith("seqrun")):
            found += [f"imports {node.module}.{a.name}" for a in node.names
                      if a.name.startswith("_") and not a.name.startswith("__")]
        elif (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
              and node.value.id in EXECUTOR_NAMES and node.attr.startswith("_")
              and not node.attr.startswith("__")):
            found.append(f"reads {node.value.id}.{node.attr} (line {node.lineno})")
    return found


def test_no_module_uses_another_modules_private_names():
    """What two modules share is public (the jog once took the executor's ``_cause`` and
    ``_halt_fields``; they are ``seqrun.results.fault_cause`` / ``halt_fields`` now)."""
    uses = [f"{short(m)} {use}" for m, path in sorted(MODULES.items())
            for use in private_uses(path)]
    assert uses == []


#: What only the service layer may hold of a run: the executor and its hooks.
EXECUTOR_HANDLES = {"executor", "idle_hooks", "on_executor", "listeners"}


def executor_handles(path: Path) -> list[str]:
    """Names, attributes, parameters and keywords of :data:`EXECUTOR_HANDLES` in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        name = (node.id if isinstance(node, ast.Name) else
                node.attr if isinstance(node, ast.Attribute) else
                node.arg if isinstance(node, (ast.arg, ast.keyword)) else None)
        if name in EXECUTOR_HANDLES:
            found.append(f"{name} (line {node.lineno})")
    return found


@pytest.mark.parametrize("module", sorted(m for m in MODULES if matches(m, FACES)))
def test_faces_go_through_the_session_and_nothing_else(module):
    """Issue 10.1: no face imports the executor (above) nor holds one handed out by the
    service layer: the displays subscribe to the session's events and render in its idle
    hook, `seqrun run` gives the session its run control, the result says what latched."""
    assert executor_handles(MODULES[module]) == []


def import_graph() -> dict[str, list[str]]:
    """Every seqrun module -> the seqrun modules it imports, however (at the top, inside a
    function, for the type checker only)."""
    return {m: sorted(seqrun_imports(m, type_only=True)) for m in MODULES}


def import_circles(graph: dict[str, list[str]]) -> list[list[str]]:
    """Strongly connected groups of modules (Tarjan) of an import graph: modules that
    import each other, directly or round a loop."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph[node]:
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            group = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                group.append(member)
                if member == node:
                    break
            if len(group) > 1:
                circles.append(sorted(short(m) for m in group))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return circles


def test_no_modules_import_each_other_in_a_circle():
    """Not even through an import for the type checker only (the step kinds once took
    ResolvedStep from the loader and Checker from the validation that imports them; they
    are the step layer's own now). A package's ``__init__`` handing on its modules' names
    counts: it is what an ``import seqrun.x`` runs."""
    assert import_circles(import_graph()) == []


def test_a_circle_is_found():
    graph = {"seqrun.a": ["seqrun.b"], "seqrun.b": ["seqrun.c"], "seqrun.c": ["seqrun.a"],
             "seqrun.d": ["seqrun.a"]}
    assert import_circles(graph) == [["a", "b", "c"]]


# --------------------------------------------------------------------------- the floors
#: Scripts beside the package that import it: rooms of the house too (on top of it).
SCRIPT_FOLDERS = ("bench", "tools")


def room_of(module: str) -> str:
    """The room a module stands in: its folder of seqrun/ (``seqrun.service``), or the
    module itself at the package's top (``seqrun.executor``); a script's folder."""
    parts = module.split(".")
    return parts[0] if parts[0] in SCRIPT_FOLDERS else ".".join(parts[:2])


def room_graph() -> dict[str, list[str]]:
    """Every room -> the rooms it imports, however (at the top, inside a function, for the
    type checker only), the scripts of bench/ and tools/ with them."""
    imports = {m: seqrun_imports(m, type_only=True) for m in MODULES}
    for folder in SCRIPT_FOLDERS:
        for path in sorted((ROOT / folder).glob("*.py")):
            name = f"{folder}.{path.stem}"
            found = imported_modules(path, name, type_only=True)
            imports[name] = {m for m in found if m in MODULES}
    graph: dict[str, set[str]] = {}
    for module, targets in imports.items():
        own = room_of(module)
        graph.setdefault(own, set()).update(room_of(t) for t in targets)
        graph[own].discard(own)
    return {room: sorted(targets) for room, targets in graph.items()}


def test_no_folders_import_each_other_in_a_circle():
    """No arrow runs back up between rooms either: the service drew report.html with the
    report's package, which read the run folder's files through the service's run log
    (seqrun/runfolder/ is below both now)."""
    assert import_circles(room_graph()) == []


def test_a_circle_between_rooms_is_found():
    assert room_of("seqrun.service.runlog") == "seqrun.service"
    assert room_of("seqrun.executor") == "seqrun.executor"
    assert room_of("bench.soak") == "bench"
    graph = {"seqrun.service": ["seqrun.report"], "seqrun.report": ["seqrun.service"]}
    assert import_circles(graph) == [["report", "service"]]


def floor_bound(text: str) -> int:
    """The most floors the "Layers" section of docs/architecture.md allows the rooms."""
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    (bound,) = re.findall(r"at most (\d+) floors", section)
    return int(bound)


def longest_chain(graph: dict[str, list[str]]) -> list[str]:
    """The longest import chain of an import graph, top room first: its length is the
    number of floors the rooms stand on (floor 1 imports no other room). An import that
    closes a circle is not followed (the circle is a failure of its own, above)."""
    chains: dict[str, list[str]] = {}
    climbing: set[str] = set()

    def chain(room: str) -> list[str]:
        if room not in chains:
            climbing.add(room)
            below = [chain(t) for t in graph.get(room, ()) if t not in climbing]
            climbing.discard(room)
            chains[room] = [room] + max(below, key=len, default=[])
        return chains[room]

    return max((chain(room) for room in sorted(graph)), key=len, default=[])


def test_the_rooms_stand_on_at_most_the_floors_the_doc_allows():
    """Issue 25: the import picture on at most ~10 floors (there were 14: a program file
    that only imported the entry module, the loop importing the validation, the step
    kinds a floor above the drivers for three value types, ...). A room is a folder of
    seqrun/ or a module at its top, bench/ or tools/; its floor is one above the highest
    room it imports."""
    bound = floor_bound(DOC.read_text(encoding="utf-8"))
    chain = longest_chain(room_graph())
    assert len(LAYERS) <= bound
    assert len(chain) <= bound, f"{len(chain)} floors: " + " -> ".join(map(short, chain))


def test_the_floors_are_counted():
    graph = {"seqrun.cli": ["seqrun.service", "seqrun.errors"],
             "seqrun.service": ["seqrun.errors"], "seqrun.errors": [], "bench": ["seqrun.cli"]}
    assert longest_chain(graph) == ["bench", "seqrun.cli", "seqrun.service", "seqrun.errors"]
    assert floor_bound("## Layers\nat most 9 floors (the rooms)\n## Next\nat most 3 floors") == 9
