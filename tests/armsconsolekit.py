"""The console of two arms (issue 28) on two arm sessions over the built-in simulator, one
each (its own simulated bus), every frame each session sends recorded per arm.

``arms_setup(folder)`` builds a campaign with ``[arms.A]`` and ``[arms.B]`` (B 900 mm away,
turned 180 degrees) on the console tests' project tree; ``faults``: simulator fault specs per
arm (``{"B": ["all:drop_acks=1.0@0"]}``: B's modules stop answering).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))

from consolekit import Wire, project_tree  # noqa: E402

TWO_ARMS = """\
[campaign]
name = "Two-arm console"

[arms.A]
arm = "lwa3"
base = { position_mm = [0, 0, 0], rpy_deg = [0, 0, 0] }

[arms.B]
arm = "lwa3"
base = { position_mm = [0, 900, 0], rpy_deg = [0, 0, 180] }
"""


@dataclass
class ArmsSetup:
    folder: Path
    project: Any
    contexts: dict[str, Any]
    sessions: Any
    wires: dict[str, Wire]
    runs: Path

    def app(self, **kw: Any):
        from seqrun.console.arms import create_arms_app
        from seqrun.console.catalog import Catalog

        return create_arms_app(self.sessions, Catalog(self.project, self.runs), self.contexts,
                               **kw)

    def close(self) -> None:
        self.sessions.close()


def arms_setup(folder: Path, *, faults: dict[str, list[str]] | None = None,
               campaign: str = TWO_ARMS, arm_files: dict[str, str] | None = None,
               **session_kw: Any) -> ArmsSetup:
    """``arm_files``: arm files to add to the campaign, name -> YAML appended to the
    shipped LWA 3's (tools, say); ``campaign`` names them."""
    from wrapbus import WrapBus

    from seqrun.sequence.project import open_project
    from seqrun.service.arm_context import resolve_contexts
    from seqrun.service.arms_console import ArmSessions
    from seqrun.service.connection import parse_faults
    from seqrun.service.session import ArmSession

    project_tree(folder)
    for name, extra in (arm_files or {}).items():
        lwa3 = (folder / "arms" / "lwa3.yaml").read_text()
        (folder / "arms" / f"{name}.yaml").write_text(lwa3 + "\n" + extra)
    (folder / "seqrun.toml").write_text(campaign)
    project = open_project(folder)
    contexts = {c.arm_id: c for c in resolve_contexts(project=project, sim=True)}
    runs = folder / "runs"
    wires: dict[str, Wire] = {}
    made: dict[str, Any] = {}
    for arm_id, context in contexts.items():
        connection = context.open_connection(
            faults=parse_faults((faults or {}).get(arm_id, [])) or None)
        wires[arm_id] = Wire()
        connection.bus = WrapBus(connection.bus, before_send=wires[arm_id].record)
        arm = context.arm.with_zero_reference("park")
        made[arm_id] = ArmSession(arm, connection, project=project, log_root=runs,
                                  arm_id=arm_id, **session_kw)
    sessions = ArmSessions(made, bases={a: c.base for a, c in contexts.items()})
    return ArmsSetup(folder, project, contexts, sessions, wires, runs)
