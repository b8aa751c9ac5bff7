"""What the console lists from the project: poses, sequences, past runs, and a sequence's
validation findings with its dry-run report.

Nothing here touches the bus: a check is ``seqrun validate``'s own service call
(:func:`seqrun.service.checking.check_sequence`: the static checks, then the dry run on
the simulator at virtual time), starting from where the arm stands now.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from seqrun.errors import Refused, UserInputError

if TYPE_CHECKING:
    from seqrun.sequence.project import Project


@dataclass(frozen=True)
class Catalog:
    """The project the console serves: where its poses, sequences and runs are."""

    project: Project
    #: Where run folders are (the session's log root; default the project's runs dir).
    runs_dir: Path

    @property
    def sequences_dir(self) -> Path:
        return self.project.root / "sequences"

    # -- poses -------------------------------------------------------------------------
    def poses(self, arm: Any = None) -> list[dict[str, Any]]:
        """Every pose file on the project's pose path (campaign first, then the shipped).
        With ``arm``: ``move_target`` says whether a move may go there, and ``why`` not (a
        joint outside the arm file's limits)."""
        from seqrun.service.poses import list_poses

        found: list[dict[str, Any]] = []
        for name, path, pose, error in list_poses(self.project.pose_path):
            if pose is None:
                found.append({"name": name, "file": str(path), "error": error,
                              "move_target": False, "why": error})
                continue
            entry: dict[str, Any] = {"name": name, "file": str(path),
                                     "description": pose.description,
                                     "joints_deg": dict(pose.joints_deg)}
            if arm is not None:
                outside = _outside_limits(arm, pose.joints_deg)
                entry["move_target"] = not outside
                if outside:
                    entry["why"] = (f"{path}: {'; '.join(outside)}: not a move target "
                                    "(a sequence may start there and move back inside)")
            found.append(entry)
        return found

    # -- sequences ---------------------------------------------------------------------
    def sequences(self) -> list[dict[str, str]]:
        """The sequences a run may name: every ``*.yaml`` under the folder that is one
        (a symbolic link is listed when what it points to lies inside the folder, and then
        runs; one pointing outside is neither listed nor run)."""
        folder = self.sequences_dir
        if not folder.is_dir():
            return []
        found = []
        for path in sorted(folder.rglob("*.yaml")):
            name = path.relative_to(folder).as_posix()
            try:
                target = self.sequence_path(name)
            except Refused:
                continue
            found.append({"name": name, "file": str(target)})
        return found

    def sequence_path(self, name: str) -> Path:
        """The file of a listed sequence; a name outside the sequences folder is refused."""
        folder = self.sequences_dir.resolve()
        try:
            path = (folder / name).resolve()
            ok = path.is_relative_to(folder) and path.suffix == ".yaml" and path.is_file()
        except (OSError, ValueError):  # a NUL in the name, a name too long, a loop
            ok = False
        if not ok:
            raise Refused(f"unknown sequence '{name}' (see GET /api/v1/sequences)")
        return path

    def shutdown_sequence(self) -> Path:
        """The project's shutdown.yaml, else the shipped one (to Totem, then power-off)."""
        from seqrun.shipped import shipped_dir

        for folder in (self.sequences_dir, shipped_dir("sequences")):
            if (folder / "shutdown.yaml").is_file():
                return folder / "shutdown.yaml"
        raise Refused("no shutdown.yaml among the project's or the shipped sequences")

    def check(self, name: str, start_deg: Mapping[str, float] | None, *,
              started: bool) -> dict[str, Any]:
        """Validation findings (``file:line:col``) and, when valid, the dry run's report
        (simulator, virtual time) from ``start_deg`` (default: the Park pose), by the same
        service call as ``seqrun validate``."""
        from seqrun.service.checking import check_sequence

        path = self.sequence_path(name)
        try:
            check = check_sequence(path, start_deg=start_deg, started=started,
                                   start_label="the arm's position now",
                                   project_dir=self.project.root)
        except (UserInputError, OSError) as exc:
            raise Refused(f"{name}: {exc}") from None
        # (valid: the checks found no error; whether the dry run passed is its own)
        out: dict[str, Any] = {"sequence": name, "file": str(path),
                               "valid": check.static.valid,
                               "errors": [e.as_dict() | {"text": str(e)} for e in check.errors],
                               "notes": [n.as_dict() | {"text": f"{n.file}:{n.line}:{n.column}: "
                                                                f"note: {n.message}"}
                                         for n in check.notes],
                               "steps": [], "dry_run": None}
        if check.loaded is None:
            return out
        out["steps"] = [{"number": s.number, "kind": s.kind, "label": s.label or s.kind}
                        for s in check.loaded.steps]
        if check.dry_run is not None:
            out["dry_run"] = check.dry_run.as_dict()
            labels = {s["number"]: s["label"] for s in out["dry_run"]["steps"]}
            for step in out["steps"]:  # the executor's labels (a confirm's is its text)
                step["label"] = labels.get(step["number"]) or step["label"]
        return out

    # -- runs --------------------------------------------------------------------------
    def runs(self, arm_id: str | None = None) -> list[dict[str, Any]]:
        """Past runs, newest first, each with the id its files are served under and
        whether it has a report.html. A run of several arms: ``parts``, each arm's part
        (a run folder of its own: its id and whether it has a report.html) by arm id.
        ``arm_id``: the runs of that arm of the campaign's several, a run of several arms
        by that arm's part."""
        from seqrun.service.records import list_runs, runs_of_arm

        root = self.runs_dir.resolve()
        found = []
        listed = list_runs(root)
        for run in reversed(listed if arm_id is None else runs_of_arm(listed, arm_id)):
            folder = Path(run["folder"]).resolve()
            run_id = folder.relative_to(root).as_posix()
            parts = {a: {"id": f"{run_id}/{a}",
                         "report": (folder / a / "report.html").is_file()}
                     for a in run.get("arms") or ()}
            if arm_id is not None and arm_id in parts:  # this arm's part of it
                run_id, folder = parts[arm_id]["id"], folder / arm_id
            found.append(run | {"id": run_id, "report": (folder / "report.html").is_file(),
                                **({"parts": parts} if parts else {})})
        return found

    def run_file(self, run_id: str, name: str) -> Path:
        """A file of a run folder (report.html, report.json, ...), never outside it."""
        root = self.runs_dir.resolve()
        try:
            folder = (root / run_id).resolve()
            path = (folder / name).resolve()
            ok = (folder.is_relative_to(root) and folder != root
                  and path.is_relative_to(folder) and path.is_file())
        except (OSError, ValueError):  # a NUL in the name, a name too long, a loop
            ok = False
        if not ok:
            raise Refused(f"no file '{name}' in run '{run_id}'")
        return path


def _outside_limits(arm: Any, joints_deg: Mapping[str, float]) -> list[str]:
    """The joints of a pose outside the arm's limits, each as one phrase."""
    out = []
    for joint in arm.joints:
        value = joints_deg.get(joint.name)
        if value is None or joint.locked is not None:
            continue
        lo, hi = joint.limits_deg
        if not lo <= value <= hi:
            out.append(f"{joint.name} {value:g}° is outside its limits [{lo:g}, {hi:g}]°")
    return out
