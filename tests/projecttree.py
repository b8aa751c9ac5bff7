"""The repository's own files, and project trees of a test's own built from them.

``ROOT`` is the checkout (arms/, poses/, sequences/ at its top). :func:`make_project` lays
out a campaign under a temporary folder (seqrun.toml, arms/, poses/, sequences/), so a test
may add or change files without touching the shipped ones; the ``project`` fixture of
conftest.py is one of these.
"""

from __future__ import annotations

import functools
import importlib.util
import shutil
import textwrap
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import ModuleType

from seqrun.arm.description import ArmDescription, load_arm

ROOT = Path(__file__).resolve().parents[1]
ARM_FILE = ROOT / "arms" / "lwa3.yaml"

#: The campaign's config: its own arm file, so a test may change the arm.
CONFIG = '[campaign]\nname = "test"\narm = "arms/lwa3.yaml"\n'


@functools.cache
def tool(name: str) -> ModuleType:
    """``tools/<name>.py`` as a module (tools/ is a folder of scripts, not a package)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "tools" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@functools.cache
def shipped_arm() -> ArmDescription:
    """arms/lwa3.yaml, loaded once per process (the description is frozen)."""
    return load_arm(ARM_FILE)


def make_project(root: Path, *, sequences: Iterable[str] | str = ("startup.yaml",),
                 arm_changes: Mapping[str, str] | None = None, campaign: bool = True) -> Path:
    """``root`` as a campaign: seqrun.toml, arms/lwa3.yaml, copies of the shipped poses and
    of the shipped ``sequences`` named (``"*"``: all of them); returns ``root``.
    ``campaign=False``: no seqrun.toml (the layout from before campaigns: includes stay
    inside sequences/).

    ``arm_changes`` maps a text of the shipped arm file to its replacement; each must stand
    there exactly once (so a test notices when the arm file changes under it)."""
    (root / "arms").mkdir(parents=True)
    text = ARM_FILE.read_text(encoding="utf-8")
    for old, new in (arm_changes or {}).items():
        assert text.count(old) == 1, f"arms/lwa3.yaml changed: update {old!r} in the test"
        text = text.replace(old, new)
    (root / "arms" / "lwa3.yaml").write_text(text, encoding="utf-8")
    shutil.copytree(ROOT / "poses", root / "poses")
    (root / "sequences").mkdir()
    names = ([p.name for p in (ROOT / "sequences").glob("*.yaml")] if sequences == "*"
             else sequences)
    for name in names:
        shutil.copy(ROOT / "sequences" / name, root / "sequences" / name)
    if campaign:
        (root / "seqrun.toml").write_text(CONFIG, encoding="utf-8")
    return root


def write_sequence(project: Path, steps: str, name: str = "s.yaml", *,
                   title: str = "T") -> Path:
    """``project/sequences/name`` holding a sequence of the (dedented) ``steps``; its header
    is three lines, so the first step is on line 4."""
    path = project / "sequences" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"name: {title}\ndescription: test\nsteps:\n" + textwrap.dedent(steps),
                    encoding="utf-8")
    return path
