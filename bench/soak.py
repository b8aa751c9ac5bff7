"""A soak at virtual time: hours of random valid sequences and random faults, one process.

    .venv/bin/python bench/soak.py [--hours 8] [--seed 1] [--out bench/results/soak.json]
        [--keep DIR] [--clean 1] [--moves 8 40]
    .venv/bin/python bench/soak.py --combine A.json B.json [--out bench/results/soak.json]

Several soaks may run side by side, one process per core with different ``--seed``s;
``--combine`` adds up their figures (the memory figures stay per process).

Each run is ``seqrun run FILE --virtual-time --yes --plain [--sim-fault SPEC] --log-dir DIR``
through the real CLI, in this process (the typer app, the arm session, the executor, the
simulated wire, the run folder and report.html), one after the other until the runs'
virtual motion adds up to ``--hours``:

- the sequence is random and valid: the start-up, Park -> Totem, ``--moves`` moves of random
  joints to random targets at random speeds (some to Op-safe or Totem), dwells and waits
  for position, back to Totem and a checkpoint there; drawn again until
  ``seqrun validate --static`` passes it;
- the runs come in rounds of the six fault kinds (``tow_error``, ``halt``, ``no_ack``,
  ``drop_acks`` at a random rate, ``stuck``, ``missing``) and ``--clean`` runs without a
  fault, shuffled; a fault strikes a random module (or all), at a random time within the
  sequence's planned duration.

Each run is judged from its run folder, as an operator would read it:

- a fault that happened (its time before the run's end) must end the run with exit 3, a
  ``fault`` no earlier than the injection and on the faulted module, and a Halt broadcast
  on the bus at or after the injection: *ended in Halt*. The exceptions are faults no
  runner can see, which must pass: a ``stuck`` joint that is not commanded to move (its
  plan stays within the position tolerance of where it stuck) and ``drop_acks`` whose
  every lost answer was a read that was retried (a ``retry`` event each). Anything else is
  a *missed halt*. A fault in the last 0.2 s of a run may go unseen (a silence is seen
  50 ms after an answer is due): counted apart;
- a run without a fault (or whose fault time lies after its end) must pass: anything else
  is a *spurious fault*, as is a fault before the injection or on another module.

Figures: runs, faults injected, faults ending in Halt, missed halts, spurious faults, the
slope of the resident set over the hours of virtual motion (least squares over the runs
after the first, KB/h; the RSS is read after each run), open files and threads before the
first run and after the last. Before the first run come two warm-up runs, not counted (a
clean one and a faulted one: what every run needs is then loaded for good - modules,
caches, matplotlib's font files). Wall time depends on the host's load (reported).

Run folders are deleted after each run unless ``--keep`` (kept anyway: the folders of runs
judged wrong).

SIGTERM or Ctrl-C (SIGINT) ends the soak after the run under way, with the figures so far
(exit 130). During a run the run's own handlers have the signal (it halts that run, exit
130, as ``seqrun run`` does); the soak sees that exit and stops; between runs its own
handlers take it. Without this the soak went on with the next run after each SIGTERM.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import random
import re
import shutil
import socket
import signal
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

from seqrun.sim.faults import FAULT_KINDS, Fault  # noqa: E402

#: Faults this close to a run's end may go unseen (a silence is seen one response timeout
#: after the answer is due; a state read comes every cycle).
UNSEEN_S = 0.2
#: Faults are injected from here on (after the start-up's Reset, which clears a module's
#: error: a fault before it is a fault the sequence itself clears).
FIRST_FAULT_S = 0.5
#: Joint ranges of the random moves (user degrees): well inside the limits, and mostly
#: clear of the desk (validation has the last word).
RANGES = {"j1": (-150, 150), "j2": (-60, 60), "j4": (-80, 80), "j5": (-150, 150),
          "j6": (-80, 80), "j7": (-150, 150)}
BROADCAST_HALT = (0x100, "02")


# ---------------------------------------------------------------------------- sequences
def make_project(root: Path) -> Path:
    """A project with the shipped arm, poses and start-up; returns its sequences folder."""
    for name in ("arms", "poses"):
        shutil.copytree(ROOT / name, root / name, dirs_exist_ok=True)
    (root / "sequences").mkdir(parents=True, exist_ok=True)
    shutil.copy(ROOT / "sequences" / "startup.yaml", root / "sequences")
    return root / "sequences"


def random_steps(rng: random.Random, moves: int) -> list[str]:
    steps = ["  - include: startup.yaml",
             "  - move: {pose: totem, velocity_scale: 0.5, label: Up to Totem}"]
    for k in range(moves):
        scale = round(rng.uniform(0.2, 1.0), 2)
        if rng.random() < 0.1:
            pose = rng.choice(["opsafe", "totem"])
            steps.append(f"  - move: {{pose: {pose}, velocity_scale: {scale}, "
                         f"label: move {k + 1}}}")
        else:
            joints = rng.sample(sorted(RANGES), rng.randint(1, 4))
            target = ", ".join(f"{j}: {rng.uniform(*RANGES[j]):.1f}" for j in sorted(joints))
            steps.append(f"  - move: {{joints: {{{target}}}, velocity_scale: {scale}, "
                         f"label: move {k + 1}}}")
        roll = rng.random()
        if roll < 0.15:
            steps.append(f"  - wait: {{seconds: {rng.uniform(0.1, 2.0):.2f}}}")
        elif roll < 0.25:
            steps.append("  - wait: {until: in_position}")
    steps += ["  - move: {pose: totem, velocity_scale: 0.5, label: Back to Totem}",
              "  - checkpoint: {pose: totem, label: At Totem}"]
    return steps


def random_sequence(rng: random.Random, folder: Path, name: str,
                    moves: tuple[int, int]) -> tuple[Path, float]:
    """A random sequence that passes static validation, and its planned duration (s)."""
    from seqrun.sequence.checks import static_check

    path = folder / f"{name}.yaml"
    for _ in range(100):
        steps = random_steps(rng, rng.randint(*moves))
        path.write_text(f"name: {name}\ndescription: random soak sequence\nsteps:\n"
                        + "\n".join(steps) + "\n")
        check = static_check(path)
        if check.valid:
            planned = sum(c.duration_s for c in check.clearances)
            planned += sum(float(m) for m in re.findall(r"seconds: ([0-9.]+)", path.read_text()))
            return path, planned
    raise RuntimeError("no valid random sequence in 100 draws: the ranges are wrong")


class FaultDeck:
    """Rounds of every fault kind once and ``clean`` runs without a fault, shuffled; each
    fault on a random module (or all), at a random time, drop_acks at a random rate."""

    def __init__(self, rng: random.Random, clean: int = 1) -> None:
        self.rng = rng
        self.clean = clean
        self.deck: list[str | None] = []

    def draw(self, planned_s: float) -> Fault | None:
        if not self.deck:
            self.deck = [*FAULT_KINDS, *[None] * self.clean]
            self.rng.shuffle(self.deck)
        kind = self.deck.pop()
        if kind is None:
            return None
        module = None if self.rng.random() < 0.1 else self.rng.randint(1, 7)
        at = round(self.rng.uniform(FIRST_FAULT_S, max(FIRST_FAULT_S + 0.1, planned_s)), 3)
        rate = round(10 ** self.rng.uniform(-2.3, -0.3), 4) if kind == "drop_acks" else None
        return Fault(module, kind, at, rate)


# ---------------------------------------------------------------------------- one run
@dataclass
class Verdict:
    spec: str | None
    exit_code: int
    duration_s: float
    outcome: str            # clean, halted, unobservable, unseen_late, missed_halt, spurious
    detail: str = ""
    halt_latency_s: float | None = None
    wall_s: float = 0.0


def run_cli(sequence: Path, folder: Path, fault: Fault | None, extra: list[str] = ()):
    from typer.testing import CliRunner

    import seqrun.cli  # noqa: F401  (registers the commands)
    from seqrun.cli.app import app

    args = ["run", str(sequence), "--virtual-time", "--yes", "--plain",
            "--log-dir", str(folder)]
    if fault is not None:
        args += ["--sim-fault", fault.spec]
    return CliRunner().invoke(app, [*args, *extra])


def _frames(folder: Path, shift: float) -> list[tuple[float, int, str, bool]]:
    """(run-clock time, id, data hex, sent) of every frame of the trace."""
    from seqrun.service.runlog import trace_text

    out = []
    for line in trace_text(folder).splitlines():
        stamp, _, frame, direction = line.split()
        can_id, _, data = frame.partition("#")
        out.append((round(float(stamp[1:-1]) + shift, 6), int(can_id, 16), data.upper(),
                    direction == "T"))
    return out


def _events(folder: Path) -> list[dict]:
    from seqrun.runfolder.logfile import read_lines
    from seqrun.runfolder.names import events_path

    path = events_path(folder)
    if path is None:
        raise FileNotFoundError(f"{folder}: no events.jsonl.gz (nor an older events.jsonl)")
    return [json.loads(line) for line in read_lines(path) if line.strip()]


def judge(fault: Fault | None, result, folder: Path, arm) -> Verdict:
    """The verdict on one run (see the module docstring)."""
    report = json.loads((folder / "report.json").read_text())
    code = result.exit_code
    duration = float(report.get("duration_s") or 0.0)
    spec = fault.spec if fault is not None else None
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        return Verdict(spec, code, duration, "spurious", f"exception {result.exception!r}")
    happened = fault is not None and fault.at < duration
    if not happened:
        if code == 0:
            return Verdict(spec, code, duration, "clean")
        return Verdict(spec, code, duration, "spurious",
                       f"exit {code} without a fault: {report.get('message')}")
    assert fault is not None
    events = _events(folder)
    started = next(e for e in events if e["type"] == "run_started")
    frames = _frames(folder, started["clock_s"] - started["start_epoch_s"])
    fault_event = next((e for e in events if e["type"] == "fault"), None)
    if code == 3 and fault_event is not None:
        reported = report.get("fault") or {}
        if fault_event["t"] < fault.at - 1e-6:
            return Verdict(spec, code, duration, "spurious",
                           f"fault at {fault_event['t']} before the injection at {fault.at}")
        if fault.module is not None and reported.get("module") not in (fault.module, None):
            return Verdict(spec, code, duration, "spurious",
                           f"fault names module {reported.get('module')}, not {fault.module}")
        halts = [t for t, can_id, data, sent in frames
                 if sent and can_id == BROADCAST_HALT[0] and data.startswith(BROADCAST_HALT[1])
                 and t >= fault.at - 1e-6]
        if halts and reported.get("halt_sent"):
            return Verdict(spec, code, duration, "halted",
                           halt_latency_s=round(halts[0] - fault.at, 6))
        return Verdict(spec, code, duration, "missed_halt",
                       f"exit 3 but no Halt on the bus after {fault.at} s")
    if code == 0:
        why = _unobservable(fault, events, frames, arm)
        if why:
            return Verdict(spec, code, duration, "unobservable", why)
        if fault.at >= duration - UNSEEN_S:
            return Verdict(spec, code, duration, "unseen_late")
        return Verdict(spec, code, duration, "missed_halt", "passed with the fault")
    return Verdict(spec, code, duration, "missed_halt",
                   f"exit {code}: {report.get('message')}")


def _unobservable(fault: Fault, events: list[dict], frames, arm) -> str:
    """Why a run that passed with ``fault`` could not have seen it ('' if it could)."""
    modules = [fault.module] if fault.module is not None else [j.module for j in arm.joints]
    if fault.kind == "stuck":
        index = [i for i, j in enumerate(arm.joints) if j.module in modules]
        before = [e for e in events if e["type"] in ("setpoint", "measurement")
                  and e["t"] <= fault.at]
        if not before:
            return ""
        where = before[-1].get("measured_deg") or before[-1].get("joints_deg")
        worst = 0.0
        for e in events:
            if e["type"] == "setpoint" and e["t"] > fault.at:
                worst = max(worst, max(abs(e["planned_deg"][i] - where[i]) for i in index))
        bound = arm.control.position_tolerance_deg
        return f"stuck joint planned within {worst:.3f} deg" if worst <= bound else ""
    if fault.kind == "drop_acks":
        lost = {m: 0 for m in modules}
        waiting = {m: False for m in modules}
        for t, can_id, _, sent in frames:
            if t < fault.at:
                continue
            m = can_id & 0x1F
            if m not in lost:
                continue
            if sent and (can_id & ~0x1F) in (0x0C0, 0x0E0):
                lost[m] += waiting[m]
                waiting[m] = True
            elif not sent and (can_id & ~0x1F) == 0x0A0:
                waiting[m] = False
        retried = {m: sum(1 for e in events if e["type"] == "retry" and e["t"] >= fault.at
                          and (e.get("module") == m or m in (e.get("modules") or ())))
                   for m in modules}
        if all(lost[m] <= retried[m] for m in modules):
            return f"lost answers {sum(lost.values())}, all retried reads"
    return ""


# ---------------------------------------------------------------------------- the soak
def rss_kb() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024


def open_files() -> int:
    return len(os.listdir("/proc/self/fd"))


def os_threads() -> int:
    return len(os.listdir("/proc/self/task"))


@dataclass
class SoakResult:
    virtual_s: float = 0.0
    wall_s: float = 0.0
    runs: int = 0
    faults_injected: int = 0          # fault time before the run's end
    faults_ended_in_halt: int = 0
    faults_unobservable: int = 0      # passed, and no runner could have seen them
    faults_unseen_late: int = 0       # in the last UNSEEN_S of a run, passed
    faults_after_the_end: int = 0     # drawn for a time the run did not reach
    missed_halts: int = 0
    spurious_faults: int = 0
    clean_runs: int = 0
    kinds: dict[str, dict[str, int]] = field(default_factory=dict)
    halt_latency_max_s: dict[str, float] = field(default_factory=dict)
    rss_kb: list[tuple[float, int]] = field(default_factory=list)   # (virtual h, KB)
    rss_slope_kb_per_h: float | None = None
    #: After the warm-up and after the last run.
    open_files: tuple[int, int] = (0, 0)
    threads: tuple[int, int] = (0, 0)          # Python threads
    os_threads: tuple[int, int] = (0, 0)
    before_warm_up: dict[str, int] = field(default_factory=dict)
    wrong: list[dict] = field(default_factory=list)
    #: The signal that ended the soak before its hours (None: it ran them all).
    stopped_by: str | None = None


#: The exit code of a run an operator stopped (SIGINT, SIGTERM): seqrun.results'.
EXIT_OPERATOR_ABORT = 130


class StopSignals:
    """SIGINT and SIGTERM between runs: noted, the soak stops after the run under way
    (the handlers the soak found are back when it ends).

    During a run the run's handlers have the signal; one that comes after the run's loop
    has ended (its report being written) asks a loop that is gone and the run's exit code
    does not show it. Python writes the number of every signal it handles, whoever's
    handler, to the wake-up file descriptor: :meth:`came_during_run` reads it after each
    run, so no SIGTERM is lost."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.received: str | None = None
        self._saved: dict[int, object] = {}
        self._wake_read, self._wake_write = socket.socketpair()
        self._saved_wakeup = -1

    def _note(self, signum: int, frame=None) -> None:
        self.received = signal.Signals(signum).name

    def came_during_run(self) -> str | None:
        """SIGINT or SIGTERM handled since the last call (by the soak's handler or a
        run's), else None."""
        try:
            numbers = self._wake_read.recv(4096)
        except BlockingIOError:
            return None
        names = [signal.Signals(n).name for n in numbers if n in self.SIGNALS]
        return names[0] if names else None

    def __enter__(self) -> StopSignals:
        for sock in (self._wake_read, self._wake_write):
            sock.setblocking(False)
        self._saved_wakeup = signal.set_wakeup_fd(self._wake_write.fileno(),
                                                  warn_on_full_buffer=False)
        for signum in self.SIGNALS:
            self._saved[signum] = signal.signal(signum, self._note)
        return self

    def __exit__(self, *exc) -> None:
        for signum, old in self._saved.items():
            signal.signal(signum, old)  # type: ignore[arg-type]
        signal.set_wakeup_fd(self._saved_wakeup)
        self._wake_read.close()
        self._wake_write.close()


def slope(points: list[tuple[float, int]], after_h: float = 0.0) -> float | None:
    """Least-squares slope (KB per virtual hour) of the RSS after the first run (and, with
    ``after_h``, from that virtual hour on: once the allocator and caches have settled)."""
    points = [p for p in points[1:] if p[0] >= after_h]
    if len(points) < 2:
        return None
    import numpy as np

    x = np.array([p[0] for p in points])
    y = np.array([p[1] for p in points], dtype=float)
    if np.ptp(x) == 0:
        return None
    return float(np.polyfit(x, y, 1)[0])


def rss_by_hour(points: list[tuple[float, int]]) -> list[int]:
    """The RSS (MB) after the last run of each whole virtual hour: whether it settles."""
    hours = int(points[-1][0]) if points else 0
    return [round(max((p for p in points if p[0] <= h), key=lambda p: p[0])[1] / 1024)
            for h in range(1, hours + 1) if any(p[0] <= h for p in points)]


def warm_up(sequences: Path, work: Path, stop: StopSignals | None = None) -> None:
    """A clean run and a faulted one (not counted): what every later run needs is then
    loaded for good (modules, caches, matplotlib's font files, the bold one of a fault's
    label), so that what is open after the last run compares with what was before."""
    path = sequences / "warm-up.yaml"
    path.write_text("name: warm-up\ndescription: soak warm-up\nsteps:\n"
                    "  - include: startup.yaml\n  - move: {pose: totem, velocity_scale: 0.5}\n")
    for n, fault in enumerate((None, Fault(4, "tow_error", 3.0))):
        folder = work / f"warm-up-{n}"
        result = run_cli(path, folder, fault)
        if stop is not None and (stop.received or result.exit_code == EXIT_OPERATOR_ABORT):
            stop.received = stop.received or "a signal during the warm-up"
            shutil.rmtree(folder, ignore_errors=True)
            break
        if result.exit_code != (0 if fault is None else 3):
            raise RuntimeError(f"warm-up run {n} exited {result.exit_code}:\n{result.output}")
        shutil.rmtree(folder, ignore_errors=True)
    path.unlink()


def soak(virtual_s: float, *, seed: int = 1, clean: int = 1,
         moves: tuple[int, int] = (8, 40), keep: Path | None = None,
         progress=print) -> SoakResult:
    rng = random.Random(seed)
    deck = FaultDeck(rng, clean)
    work = Path(tempfile.mkdtemp(prefix="seqrun-soak-"))
    out = SoakResult()
    try:
        with StopSignals() as stop:
            _soak(out, work, rng, deck, virtual_s, moves, keep, progress, stop)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out


def _soak(out: SoakResult, work: Path, rng: random.Random, deck: FaultDeck,
          virtual_s: float, moves: tuple[int, int], keep: Path | None, progress,
          stop: StopSignals) -> None:
    from seqrun.arm.description import load_arm

    sequences = make_project(work / "project")
    arm = load_arm(work / "project" / "arms" / "lwa3.yaml")
    gc.collect()
    out.before_warm_up = {"open_files": open_files(),
                          "threads": threading.active_count(), "os_threads": os_threads()}
    warm_up(sequences, work, stop)
    gc.collect()
    files0, threads0, tasks0 = open_files(), threading.active_count(), os_threads()
    wall0 = time.perf_counter()
    while out.virtual_s < virtual_s and out.stopped_by is None:
        if stop.received:
            out.stopped_by = stop.received
            break
        n = out.runs + 1
        sequence, planned = random_sequence(rng, sequences, f"soak-{n:04d}", moves)
        fault = deck.draw(planned)
        folder = (keep or work) / f"run-{n:04d}"
        w0 = time.perf_counter()
        result = run_cli(sequence, folder, fault)
        during = stop.came_during_run()
        if result.exit_code == EXIT_OPERATOR_ABORT or stop.received or during:
            # The run took the signal (it halted, exit 130): the soak's, not the run's.
            out.stopped_by = (stop.received or during
                              or "a signal during a run (the run halted)")
            progress(f"run {n:4d} stopped by {out.stopped_by}: the soak ends here")
            shutil.rmtree(folder, ignore_errors=True)
            sequence.unlink()
            break
        verdict = judge(fault, result, folder, arm)
        verdict.wall_s = round(time.perf_counter() - w0, 2)
        _count(out, fault, verdict)
        out.virtual_s += verdict.duration_s
        out.runs = n
        if verdict.outcome in ("missed_halt", "spurious"):
            out.wrong.append({**asdict(verdict), "sequence": sequence.read_text(),
                              "folder": str(folder), "output": result.output[-2000:]})
            kept = (keep or RESULTS) / "soak-wrong" / folder.name
            if folder != kept:
                shutil.copytree(folder, kept, dirs_exist_ok=True)
                shutil.copy(sequence, kept / sequence.name)
        if keep is None:
            shutil.rmtree(folder, ignore_errors=True)
        sequence.unlink()
        gc.collect()
        out.rss_kb.append((round(out.virtual_s / 3600, 4), rss_kb()))
        progress(f"run {n:4d} {verdict.duration_s:8.1f} s virtual "
                 f"{verdict.wall_s:6.1f} s wall  {verdict.spec or '-':<24} "
                 f"exit {verdict.exit_code}  {verdict.outcome:<13} {verdict.detail}"[:160]
                 + f"  | total {out.virtual_s / 3600:.2f} h, RSS {out.rss_kb[-1][1] / 1024:.0f} MB")
    out.wall_s = round(time.perf_counter() - wall0, 1)
    gc.collect()
    out.open_files = (files0, open_files())
    out.threads = (threads0, threading.active_count())
    out.os_threads = (tasks0, os_threads())
    out.rss_slope_kb_per_h = slope(out.rss_kb)


def _count(out: SoakResult, fault: Fault | None, v: Verdict) -> None:
    kind = fault.kind if fault is not None else "none"
    per = out.kinds.setdefault(kind, {})
    per[v.outcome] = per.get(v.outcome, 0) + 1
    if fault is not None:
        if fault.at < v.duration_s:
            out.faults_injected += 1
        else:
            out.faults_after_the_end += 1
    if v.outcome == "clean":
        out.clean_runs += 1
    elif v.outcome == "halted":
        out.faults_ended_in_halt += 1
        if v.halt_latency_s is not None:
            out.halt_latency_max_s[kind] = max(out.halt_latency_max_s.get(kind, 0.0),
                                               v.halt_latency_s)
    elif v.outcome == "unobservable":
        out.faults_unobservable += 1
    elif v.outcome == "unseen_late":
        out.faults_unseen_late += 1
    elif v.outcome == "missed_halt":
        out.missed_halts += 1
    elif v.outcome == "spurious":
        out.spurious_faults += 1


def combine(shards: list[dict]) -> dict:
    """One soak's figures from several processes' (``--seed`` differing): counts added,
    kinds merged, the worst halt latency per kind; RSS slopes, open files and threads stay
    per process (each is its own process' memory)."""
    counted = ("virtual_s", "runs", "faults_injected", "faults_ended_in_halt",
               "faults_unobservable", "faults_unseen_late", "faults_after_the_end",
               "missed_halts", "spurious_faults", "clean_runs")
    out: dict = {name: sum(s[name] for s in shards) for name in counted}
    out["wall_s"] = max(s["wall_s"] for s in shards)   # the processes ran side by side
    kinds: dict[str, dict[str, int]] = {}
    latency: dict[str, float] = {}
    for s in shards:
        for kind, outcomes in s["kinds"].items():
            for outcome, n in outcomes.items():
                kinds.setdefault(kind, {})[outcome] = kinds.get(kind, {}).get(outcome, 0) + n
        for kind, t in s["halt_latency_max_s"].items():
            latency[kind] = max(latency.get(kind, 0.0), t)
    out["kinds"], out["halt_latency_max_s"] = kinds, latency
    out["wrong"] = [w for s in shards for w in s["wrong"]]
    out["shards"] = [memory_figures(s) for s in shards]
    return out


def memory_figures(s: dict) -> dict:
    """One process's memory figures from its result: RSS slopes (all runs, and from the
    first virtual hour on), RSS after each whole hour, first, last and largest; open files
    and threads."""
    points = s["rss_kb"]   # none when the soak was stopped before its first run
    return {"seed": s["seed"], "hours": s["hours"], "runs": s["runs"],
            "rss_slope_kb_per_h": s["rss_slope_kb_per_h"],
            "rss_slope_after_1h_kb_per_h": slope(points, after_h=1.0),
            "rss_mb_by_hour": rss_by_hour(points),
            "rss_mb_first_last": ([round(points[0][1] / 1024), round(points[-1][1] / 1024)]
                                  if points else ["-", "-"]),
            "rss_mb_max": round(max(kb for _, kb in points) / 1024) if points else None,
            "open_files": s["open_files"], "threads": s["threads"],
            "os_threads": s["os_threads"], "machine": s["machine"],
            "load_avg_at_end": s["load_avg_at_end"]}


def print_figures(r: dict) -> None:
    print(f"\n{r['virtual_s'] / 3600:.2f} h of virtual motion in {r['wall_s'] / 60:.1f} min wall "
          f"({r['virtual_s'] / max(r['wall_s'], 1e-9):.1f}x real time), {r['runs']} runs "
          f"({r['clean_runs']} clean)")
    print(f"faults injected {r['faults_injected']}: ended in Halt {r['faults_ended_in_halt']}, "
          f"unobservable (passed) {r['faults_unobservable']}, in the last {UNSEEN_S} s and "
          f"unseen {r['faults_unseen_late']}; drawn after the run's end "
          f"{r['faults_after_the_end']}")
    print(f"missed halts {r['missed_halts']}, spurious faults {r['spurious_faults']}")
    for s in r.get("shards") or [memory_figures(r)]:
        rss = s["rss_mb_first_last"]
        slope_kb = s["rss_slope_kb_per_h"]
        settled = s.get("rss_slope_after_1h_kb_per_h")
        print(f"seed {s.get('seed')}: RSS slope "
              f"{'-' if slope_kb is None else round(slope_kb)} KB/h, after the first hour "
              f"{'-' if settled is None else round(settled)} KB/h (RSS {rss[0]} MB after "
              f"the first run, {rss[1]} MB after the last; after each hour "
              f"{s['rss_mb_by_hour']} MB); after the warm-up -> after the "
              f"last run: open files {s['open_files'][0]} -> {s['open_files'][1]}, Python "
              f"threads {s['threads'][0]} -> {s['threads'][1]}, OS threads "
              f"{s['os_threads'][0]} -> {s['os_threads'][1]}")
    print("per kind: " + "; ".join(f"{k} {v}" for k, v in sorted(r["kinds"].items())))
    print("worst halt latency per kind (s): " + ", ".join(
        f"{k} {v:.3f}" for k, v in sorted(r["halt_latency_max_s"].items())))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=8.0, help="virtual motion (hours)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--clean", type=int, default=1,
                        help="runs without a fault per round of the six fault kinds")
    parser.add_argument("--moves", type=int, nargs=2, default=(8, 40), metavar=("MIN", "MAX"))
    parser.add_argument("--keep", type=Path, help="keep every run folder here")
    parser.add_argument("--out", type=Path, default=RESULTS / "soak.json")
    parser.add_argument("--combine", type=Path, nargs="+", metavar="JSON",
                        help="no soak: add up the figures of soaks run side by side (one "
                             "process each, different --seed) and write them to --out")
    args = parser.parse_args()
    if args.combine:
        data = combine([json.loads(path.read_text()) for path in args.combine])
        write_json(args.out, data)
        print_figures(data)
        print(f"written to {args.out}")
        return
    info = machine()
    result = soak(args.hours * 3600, seed=args.seed, clean=args.clean,
                  moves=tuple(args.moves), keep=args.keep)
    data = {"machine": info, "load_avg_at_end": os.getloadavg(), "hours": args.hours,
            "seed": args.seed, **asdict(result)}
    write_json(args.out, data)
    print_figures(data)
    print(f"before the warm-up: {result.before_warm_up}")
    print(f"load average at start {info['loadavg_at_start']}; written to {args.out}")
    if result.stopped_by:
        print(f"stopped by {result.stopped_by} before {args.hours} h: the figures are the "
              "runs so far")
        sys.exit(EXIT_OPERATOR_ABORT)


if __name__ == "__main__":
    main()
