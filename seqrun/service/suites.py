"""Test suites (docs/suites.md): checked as a whole, run one sequence after another in one
arm session, reported as one junit.xml and one ctrf.json.

The faces give what is theirs (how one sequence runs on their arm, how the operator is
asked); the order, the on-error policy and the reports are here, once. Each sequence runs
through the same run path as ``seqrun run FILE`` (the session's ``run_loaded``: every
sequence passes the same gate, its own run folder, its own records).

When a sequence fails:

* a failed check or checkpoint (fault cause ``checkpoint``: the arm stood where it was
  checked, the run halted it and every module confirmed the Halt), or a sequence refused
  before it sent anything (exit 1): ``on_error`` decides; the teardown runs. The next
  sequence starts from the measured state through the same gate; on a real arm its Reset
  asks the operator before it clears the Halt (``--yes`` never answers that);
* any other fault (a module's, the bus's, a monitor's, a timeout, a Halt not confirmed by
  every module) or the operator's abort: the suite stops whatever ``on_error`` says, and
  the teardown does not run: nothing restarts the arm by itself after that.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from seqrun.defaults import EXIT_FAULT, EXIT_INVALID, EXIT_OK, EXIT_OPERATOR_ABORT
from seqrun.sequence.suite import (Suite, SuiteItem, is_suite_file, load_suite,
                                   param_texts)

if TYPE_CHECKING:
    from seqrun.results import RunResult
    from seqrun.sequence.loader import LoadedSequence
    from seqrun.service.checking import SequenceCheck

__all__ = ["SuiteCheck", "SuiteOutcome", "SuiteRun", "check_suite", "is_suite_file",
           "load_entry", "load_suite", "several_arms", "suite_folder", "param_texts", "run_suite", "suite_ctrf", "suite_junit",
           "write_suite_reports"]


# ------------------------------------------------------------------------- validation
@dataclass
class SuiteCheck:
    """One entry's check: the sequence's own (static checks and dry run) from where the
    one before left the simulated arm (``start``: the pose or where it came from)."""

    item: SuiteItem
    check: SequenceCheck | None
    start: str
    #: Why it was not checked (None: it was).
    skipped: str | None = None

    @property
    def valid(self) -> bool:
        return self.check is not None and self.check.valid

    @property
    def rehearsed_fault(self) -> bool:
        run = self.check.dry_run if self.check is not None else None
        return run is not None and run.result.exit_code == EXIT_FAULT and bool(run.faults)


def check_suite(suite: Suite, *, start: str | None = None, started: bool = False,
                arm_file: Path | None = None, speed: float = 1.0,
                project_dir: Path | None = None, dry_run: bool = True,
                each: Callable[[SuiteCheck], None] | None = None) -> list[SuiteCheck]:
    """Check every entry once (setup, sequences, teardown, in that order), each from where
    the one before leaves the arm in its dry run (without one, ``dry_run=False``: where its
    plans leave it; the first from ``start``, default Park).
    After an entry that is not valid the arm's place is unknown: the rest are checked on
    their own from ``start`` and say so. A loop's second pass starts where the last
    sequence ended: that start is checked too when ``loop`` > 1 (the first sequence again,
    from the last one's end). ``each`` is told every check as it is done."""
    from seqrun.defaults import START_POSE
    from seqrun.service.checking import check_sequence

    entries = suite.entries()
    if suite.loop > 1:   # the second pass: the first sequence from the last one's end
        entries = ([suite.setup] if suite.setup else []) + list(suite.sequences)
        entries += [suite.sequences[0]] + ([suite.teardown] if suite.teardown else [])
    checks: list[SuiteCheck] = []
    end: Mapping[str, float] | None = None
    label = start or START_POSE
    homed = started
    for item in entries:
        checked = check_sequence(item.path, start=start if end is None else None,
                                 start_deg=end, start_label=label, arm_file=arm_file,
                                 started=homed, speed=speed, project_dir=project_dir,
                                 dry_run=dry_run, params=param_texts(item))
        result = SuiteCheck(item, checked, label)
        checks.append(result)
        if each is not None:
            each(result)
        run = checked.dry_run
        if checked.valid and run is not None and run.end_deg is not None:
            end, label = run.end_deg, f"the end of {item.shown}"
            homed = homed or any(s.kind == "home" and s.status == "passed"
                                 for s in run.result.steps)
        elif (checked.valid and run is None and checked.static.final_deg
              and checked.loaded is not None):
            # no dry run (--static): where the plans leave the arm
            end, label = checked.static.final_deg, f"the planned end of {item.shown}"
            homed = homed or any(s.kind == "home" for s in checked.loaded.steps)
        else:   # unknown from here: the next from the suite's start again
            end, label, homed = None, start or START_POSE, started
    return checks


# ------------------------------------------------------------------------------ runs
@dataclass
class SuiteRun:
    """One sequence run of the suite (or one that did not run)."""

    item: SuiteItem
    status: str                 # passed | failed | aborted | not run
    exit_code: int | None
    message: str
    run_dir: Path | None = None
    result: RunResult | None = None
    started_s: float = 0.0
    duration_s: float = 0.0

    @property
    def blocks(self) -> bool:
        """After this run nothing may move the arm by itself (module docstring)."""
        if self.exit_code in (EXIT_OK, EXIT_INVALID, None):
            return False
        if self.exit_code != EXIT_FAULT:
            return True        # operator abort, usage error
        fault = (self.result.fault if self.result is not None else None) or {}
        return not (fault.get("cause") == "checkpoint" and fault.get("halt_confirmed"))


@dataclass
class SuiteOutcome:
    suite: Suite
    runs: list[SuiteRun] = field(default_factory=list)
    started_s: float = 0.0
    finished_s: float = 0.0
    #: Why the suite stopped early (None: it ran to its end).
    stopped: str | None = None

    @property
    def passed(self) -> int:
        return sum(r.status == "passed" for r in self.runs)

    @property
    def failed(self) -> int:
        return sum(r.status in ("failed", "aborted") for r in self.runs)

    @property
    def not_run(self) -> int:
        return sum(r.status == "not run" for r in self.runs)

    @property
    def exit_code(self) -> int:
        """0 all passed; 130 the operator stopped it; 3 a sequence failed with a fault
        (or the Halt of a failed check); 1 one was refused before it moved."""
        codes = {r.exit_code for r in self.runs
                 if r.status != "not run" and r.exit_code is not None}
        for code in (EXIT_OPERATOR_ABORT, EXIT_FAULT, EXIT_INVALID):
            if code in codes:
                return code
        others = codes - {EXIT_OK}
        return max(others) if others else EXIT_OK

    @property
    def verdict(self) -> str:
        return "passed" if self.failed == 0 and self.not_run == 0 else "failed"


#: How one sequence runs on the face's arm: ``(item, folder) -> SuiteRun``.
RunOne = Callable[[SuiteItem, Path], SuiteRun]


def run_suite(suite: Suite, folder: Path, run_one: RunOne, *,
              ask_continue: Callable[[SuiteRun], bool] | None = None,
              told: Callable[[str, SuiteOutcome], None] | None = None) -> SuiteOutcome:
    """Run the suite's plan into ``folder`` (one subfolder per run, ``NN-<file stem>``).

    ``ask_continue``: asked after a failed sequence when ``on_error: pause`` (None, or no
    answer: stop). ``told(text, outcome)``: the progress lines ("suite 2/5 loop 1/3: ...",
    the counts after each run, why it stopped)."""
    outcome = SuiteOutcome(suite, started_s=time.time())
    plan = suite.plan()
    say = told or (lambda text, _outcome: None)
    blocked = False
    stop_sequences = False
    for number, item in enumerate(plan, start=1):
        if item.role == "teardown" and blocked:
            outcome.runs.append(SuiteRun(item, "not run", None, "not run: the arm needs "
                                         "the operator after the fault"))
            continue
        if item.role == "sequence" and (stop_sequences or blocked):
            outcome.runs.append(SuiteRun(item, "not run", None, "not run: the suite stopped"))
            continue
        say(_progress(number, len(plan), item, suite), outcome)
        run = run_one(item, folder / f"{number:02d}-{item.path.stem}")
        outcome.runs.append(run)
        say(f"  {item.shown}: {run.status.upper()} (exit {run.exit_code}): {run.message}"
            f" - passed {outcome.passed}, failed {outcome.failed}", outcome)
        if run.status == "passed":
            continue
        if run.blocks:
            blocked = True
            outcome.stopped = (f"{item.shown} ended in a fault or an abort: the suite "
                               "stops; nothing moves the arm by itself now (no teardown)")
            say(outcome.stopped, outcome)
        elif item.role == "setup":
            stop_sequences = True
            outcome.stopped = f"the setup {item.shown} failed: no sequence runs"
            say(outcome.stopped, outcome)
        elif item.role == "sequence" and suite.on_error != "continue":
            go_on = (suite.on_error == "pause" and ask_continue is not None
                     and ask_continue(run))
            if not go_on:
                stop_sequences = True
                outcome.stopped = (f"{item.shown} failed: the suite stops (on_error: "
                                   f"{suite.on_error}); the teardown runs")
                say(outcome.stopped, outcome)
    outcome.finished_s = time.time()
    return outcome


def _progress(number: int, total: int, item: SuiteItem, suite: Suite) -> str:
    if item.role == "sequence":
        return (f"suite {number}/{total} loop {item.loop}/{suite.loop}: {item.shown}"
                + (f" ({', '.join(f'{k}={v}' for k, v in param_texts(item).items())})"
                   if item.params else ""))
    return f"suite {number}/{total} {item.role}: {item.shown}"


def run_of(item: SuiteItem, result: RunResult, folder: Path, started_s: float) -> SuiteRun:
    """A finished run as the suite reports it."""
    status = "passed" if result.exit_code == EXIT_OK else (
        "aborted" if result.exit_code == EXIT_OPERATOR_ABORT else "failed")
    return SuiteRun(item, status, result.exit_code, result.message, folder, result,
                    started_s, max(result.duration_s, 0.0))


# --------------------------------------------------------------------------- reports
def _title(run: SuiteRun) -> str:
    where = (f"loop {run.item.loop} #{run.item.index}" if run.item.role == "sequence"
             else run.item.role)
    return f"{where}: {run.item.shown}"


def suite_junit(outcome: SuiteOutcome) -> str:
    """One ``<testsuite>`` per sequence run (its steps as test cases, exactly as the run's
    own junit.xml has them; valid against Jenkins xunit's junit-10.xsd); a sequence that did
    not run is a suite of one skipped test case."""
    from xml.sax.saxutils import escape, quoteattr

    from seqrun.service.runlog import junit_testsuite

    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f"<testsuites name={quoteattr(outcome.suite.name)} "
             f'tests="{len(outcome.runs)}" failures="{outcome.failed}" errors="0">']
    for run in outcome.runs:
        name = _title(run)
        if run.result is not None:
            lines += junit_testsuite(name, run.result)
            continue
        lines += [f'<testsuite name={quoteattr(name)} tests="1" failures="0" errors="0" '
                  f'skipped="1" time="0.000">',
                  f'  <testcase classname={quoteattr(name)} name={quoteattr(run.item.shown)} '
                  'time="0">',
                  f"    <skipped message={quoteattr(run.message)}/>",
                  f"    <system-out>{escape(f'entry at {run.item.location}')}</system-out>",
                  "  </testcase>", "</testsuite>"]
    lines.append("</testsuites>")
    return "\n".join(lines) + "\n"


def suite_ctrf(outcome: SuiteOutcome) -> str:
    """CTRF (ctrf.io): one test per sequence run, its run folder and exit code in
    ``extra``; a sequence that did not run is ``skipped``."""
    from seqrun import __version__
    from seqrun.runfolder.ctrf import ctrf_report, ctrf_test

    tests = []
    for run in outcome.runs:
        status = "skipped" if run.status == "not run" else run.status
        tests.append(ctrf_test(
            _title(run), status, run.duration_s, suite=outcome.suite.name,
            message=None if run.status == "passed" else run.message,
            location=run.item.location,
            extra={"role": run.item.role, "file": str(run.item.path),
                   "exit_code": run.exit_code, "loop": run.item.loop,
                   **({"run_dir": run.run_dir.name} if run.run_dir is not None else {}),
                   **({"params": dict(run.item.params)} if run.item.params else {})}))
    return ctrf_report(tests, start_s=outcome.started_s, stop_s=outcome.finished_s,
                       version=__version__,
                       extra={"suite": outcome.suite.name, "verdict": outcome.verdict,
                              "exit_code": outcome.exit_code,
                              **({"stopped": outcome.stopped} if outcome.stopped else {})})


def write_suite_reports(folder: Path, outcome: SuiteOutcome) -> str | None:
    """junit.xml and ctrf.json in the suite's folder; the error text when one could not
    be written (the runs' own folders hold the record)."""
    from seqrun.runfolder.logfile import write_whole

    for name, text in (("junit.xml", suite_junit(outcome)), ("ctrf.json", suite_ctrf(outcome))):
        error = write_whole(folder / name, text)
        if error:
            return f"{name}: {error}"
    return None


def suite_folder(suite: Suite, log_dir: Path | None, runs_root: Path) -> Path:
    """The suite's folder (``--log-dir``, else ``<runs>/<time>-suite-<name>/``) with the
    suite file as read: what tells it from a run's folder (``seqrun runs`` and ``seqrun
    trend`` list the runs inside). An unusable one: OSError."""
    from seqrun.runfolder.logfile import write_whole
    from seqrun.runfolder.names import SUITE_NAME
    from seqrun.service.runlog import prepare_run_folder

    folder = prepare_run_folder(log_dir, f"suite-{suite.name}", runs_root)
    error = write_whole(folder / SUITE_NAME, suite.source)
    if error is not None:
        raise error
    return folder


def several_arms(suite: Suite, project_dir: Path | None = None) -> str | None:
    """Why the suite cannot run yet when its campaign names several arms (None: one arm):
    a suite is a campaign of one arm's sequences for now (docs/suites.md)."""
    from seqrun.sequence.project import project_for

    config = project_for(suite.path.resolve(), project_dir).config
    if config is None or not config.arm_ids:
        return None
    return (f"{suite.file}: suites are for a campaign of one arm for now (this campaign "
            f"names arms {', '.join(config.arm_ids)}): run its sequences one by one")


def load_entry(item: SuiteItem, *, project_dir: Path | None = None, start: str | None = None,
               arm_file: Path | None = None, started: bool = False,
               speed: float = 1.0) -> LoadedSequence:
    """An entry's sequence with its params, as ``seqrun run`` loads a file (every problem
    in one pass: :class:`SequenceInvalid`). Its checks against the arm are its run's own:
    the preflight checks it from the measured state, where the suite's previous sequence
    left the arm, before anything moves."""
    from seqrun.errors import SequenceInvalid
    from seqrun.sequence.loader import load_sequence
    from seqrun.service.checking import errors_before_bus

    params = param_texts(item)
    try:
        return load_sequence(item.path, project_root=project_dir, params=params)
    except SequenceInvalid as exc:
        raise SequenceInvalid(errors_before_bus(
            item.path, exc.errors, start=start, arm_file=arm_file, started=started,
            speed=speed, project_dir=project_dir, params=params)) from None
