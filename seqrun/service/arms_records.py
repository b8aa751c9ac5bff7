"""The records of a campaign run with several arms (docs/two-arms.md), written the same by
every face that starts one (``seqrun run`` and the console of several arms):

- each arm's part ``<run>/<id>/``: its record.json and inputs/ (the bytes validated), a
  whole run folder of its own once its run has ended;
- the run's ONE time base (:mod:`seqrun.service.time_base`), shared by every arm's run log;
- ``<run>/run.mcap``, written live (:class:`~seqrun.service.arms_mcap.ArmsMcapLog`: topics
  ``/<id>/...``, ``/tf_static`` facility -> each base), unless ``[ros] mcap = false``;
- ``<run>/arms.json`` at the end: each arm's verdict, base and start on the time base.

:meth:`ArmsRunRecords.start` writes the parts before anything is sent (a full disk is a
refusal) and opens run.mcap; :meth:`ArmsRunRecords.parts` and ``log_dirs`` go to
:func:`seqrun.service.arms_run.run_tracks`; :meth:`ArmsRunRecords.finish` closes run.mcap
and writes arms.json. Trouble after the start is said through ``warn`` (one line each);
the run goes on.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from seqrun.service import campaign_records
from seqrun.service.arm_part import ArmPart
from seqrun.service.time_base import TimeBase

__all__ = ["ArmOfRun", "ArmsRunRecords"]


@dataclass(frozen=True)
class ArmOfRun:
    """What the records say of one arm of the run: its description (zero applied), zero
    reference, arm file, bus, and base in the facility frame (None: the facility frame)."""

    arm: Any
    zero: Any
    arm_path: Path
    bus: str
    simulator: bool
    base: Any = None

    def base_transform(self) -> Any:
        from seqrun.arm.between_arms import base_of

        return base_of(self.base)

    def base_dict(self) -> dict[str, list[float]]:
        given = self.base
        return {"position_mm": list(given.position_mm) if given else [0.0, 0.0, 0.0],
                "rpy_deg": list(given.rpy_deg) if given else [0.0, 0.0, 0.0]}


class ArmsRunRecords:
    """One campaign run's records (see the module doc). Made by :meth:`start`."""

    def __init__(self, folder: Path, tracks: Mapping[str, Any], arms: Mapping[str, ArmOfRun],
                 time_base: TimeBase, log_dirs: dict[str, Path], mcap: Any,
                 warn: Callable[[str], None]) -> None:
        self.folder = folder
        self.tracks = dict(tracks)
        self.arms = dict(arms)
        self.time_base = time_base
        #: Each arm's part of the run folder (its run's ``log_dir``).
        self.log_dirs = log_dirs
        #: run.mcap's live writer (None: ``[ros] mcap = false``).
        self.mcap = mcap
        self.warn = warn
        #: Where run.mcap ended (after :meth:`finish`).
        self.mcap_path: Path | None = None

    @classmethod
    def start(cls, folder: Path, tracks: Mapping[str, Any], arms: Mapping[str, ArmOfRun],
              clock: Any, *, project: Any, warn: Callable[[str], None]) -> ArmsRunRecords:
        """Write each arm's part (OSError: a full disk, say; nothing was sent), take the
        run's time base from ``clock`` (the arms' run clock) and open run.mcap."""
        log_dirs: dict[str, Path] = {}
        for arm_id, loaded in tracks.items():
            part = folder / arm_id
            part.mkdir(parents=True, exist_ok=True)
            of = arms[arm_id]
            campaign_records.record_run(part, loaded, of.arm_path, of.bus, of.zero, arm=of.arm,
                                        arm_id=arm_id)
            log_dirs[arm_id] = part
        time_base = TimeBase.of(clock)
        mcap = _open_mcap(folder, project, {a: arms[a] for a in tracks}, time_base, warn)
        return cls(folder, tracks, arms, time_base, log_dirs, mcap, warn)

    def parts(self) -> dict[str, ArmPart]:
        """Each arm's :class:`ArmPart`: the one time base and its face of run.mcap."""
        return {a: ArmPart(a, self.time_base,
                           self.mcap.for_arm(a) if self.mcap is not None else None)
                for a in self.tracks}

    def run_options(self) -> dict[str, Any]:
        """What :func:`seqrun.service.arms_run.run_arms_live` takes from the records, the
        same for every face: each arm's part of the run folder (``log_dirs``), its
        :class:`ArmPart` (``parts``) and its zero recorder (``record_zero``)."""
        return {"log_dirs": self.log_dirs, "parts": self.parts(),
                "record_zero": self.zero_recorders()}

    def zero_recorders(self) -> dict[str, Any]:
        """Each arm's zero recorder for a ``power_off`` step (None: a simulator, whose zero
        is its power-on pose, or no store)."""
        out: dict[str, Any] = {}
        for arm_id, loaded in self.tracks.items():
            of = self.arms[arm_id]
            store = getattr(of.zero, "store", None) if of.zero is not None else None
            out[arm_id] = None if of.simulator or store is None else \
                campaign_records.zero_recorder(store, of.arm, loaded)
        return out

    def close_mcap(self) -> Path | None:
        """End run.mcap (every arm's run has ended); its trouble is one warning."""
        if self.mcap is None or self.mcap_path is not None:
            return self.mcap_path
        self.mcap_path = self.mcap.close()
        if self.mcap.dropped:
            self.warn(f"run.mcap: {self.mcap.dropped} events were dropped (its writer fell "
                      "behind); seqrun report RUN_DIR --mcap writes it whole")
        return self.mcap_path

    def finish(self, check: Any, outcome: Any) -> None:
        """Close run.mcap, then write ``<run>/arms.json`` (``check``: the
        :class:`~seqrun.service.arms_check.ArmsCheck` run; ``outcome``: its
        :class:`~seqrun.service.arms_run.ArmsOutcome`)."""
        from seqrun.service.arms_mcap import ARMS_SUMMARY

        self.close_mcap()
        try:
            (self.folder / ARMS_SUMMARY).write_text(
                json.dumps(self.summary(check, outcome), indent=2) + "\n")
        except OSError as exc:
            self.warn(f"{self.folder}/{ARMS_SUMMARY} not written ({exc.strerror or exc})")

    def summary(self, check: Any, outcome: Any) -> dict[str, Any]:
        """arms.json: the campaign run at a glance (each arm's part is a whole run folder of
        its own): each arm's verdict, its base in the facility frame and its start on the
        run's one time base."""
        time_base, mcap = self.time_base, self.mcap

        def start(o: Any) -> dict[str, Any] | None:
            report = getattr(o.outcome, "report", None) or {}
            if "clock_s" not in report:
                return None
            return {"clock_s": report["clock_s"], "epoch_s": report.get("start_epoch_s"),
                    "utc": report.get("start_utc"),
                    "after_s": round(report["clock_s"] - time_base.clock_s, 6)}

        ros: dict[str, Any] = {"mcap": None}
        if mcap is not None:
            ros = {"mcap": self.mcap_path.name if self.mcap_path is not None else None,
                   "distribution": mcap.distribution,
                   **({"error": mcap.error} if mcap.error else {}),
                   **({"dropped_events": mcap.dropped} if mcap.dropped else {}),
                   # logged later than an arm's lag allowed for (kept in order)
                   **({"reordered": mcap.reordered} if mcap.reordered else {})}
        return {"sequence": check.tracks.name, "file": check.file,
                "exit_code": outcome.exit_code, "on_fault": outcome.on_fault,
                "first_fault": outcome.first_fault, "notes": list(outcome.notes),
                "between_arms": [b.as_dict() for b in check.between],
                "time_base": time_base.as_dict(), "ros": ros,
                "arms": {a: {"status": o.result.status, "exit_code": o.result.exit_code,
                             "message": o.result.message, "halted_because_arm": o.halted_for,
                             "part": a, "start": start(o),
                             "base": self.arms[a].base_dict()}
                         for a, o in outcome.arms.items()}}


def _open_mcap(folder: Path, project: Any, arms: Mapping[str, ArmOfRun],
               time_base: TimeBase, warn: Callable[[str], None]) -> Any:
    """``<run>/run.mcap``'s live writer, unless seqrun.toml says ``[ros] mcap = false``."""
    from seqrun.service.arms_mcap import ArmsMcapLog
    from seqrun.service.mcap_log import DEFAULT_DISTRIBUTION

    ros = getattr(getattr(project, "config", None), "ros", None)
    if ros is not None and not ros.mcap:
        return None

    def said(text: str) -> None:
        warn(f"run log: {text}; the run goes on")

    return ArmsMcapLog(folder, {a: o.arm for a, o in arms.items()},
                       {a: o.base_transform() for a, o in arms.items()}, time_base.epoch_s,
                       on_error=said, distribution=ros.distribution if ros is not None
                       else DEFAULT_DISTRIBUTION)
