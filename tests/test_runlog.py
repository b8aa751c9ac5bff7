"""The run folder: a full disk, a reused or unusable --log-dir, one time base, the report's
cost per step and the report of a killed run. In process, at virtual time."""

from __future__ import annotations

import errno
import gzip
import hashlib
import json
import os
import shutil
import time
from pathlib import Path

import can
import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands on the app)
from projecttree import ROOT
from runfolder import RunFolder
from seqrun.runfolder import logfile
from seqrun.arm.description import load_arm
from seqrun.cli.app import app
from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.results import RunResult, StepResult
from seqrun.service.runlog import TRACE_FLUSH_S, RunLog, read_report, read_trace
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence

TOTEM = ROOT / "sequences" / "totem.yaml"


def _record_file(fd: int) -> bool:
    """Whether ``fd`` is a file of the run's record (record.json, inputs/), written before
    the run starts."""
    name = os.readlink(f"/proc/self/fd/{fd}")
    return "/inputs/" in name or os.path.basename(name).startswith("record.json")


class FullDisk:
    """``os.write`` for the run folder with ``budget`` bytes of space after the run's
    record (record.json, inputs/): a write that does not fit is short (what fits), the
    next one fails with ENOSPC, like a filling disk. ``record=True``: the record's files
    count too."""

    def __init__(self, budget: int, *, record: bool = False) -> None:
        self.left = budget
        self.failures = 0
        self.record = record

    def __call__(self, fd: int, data) -> int:
        if not self.record and _record_file(fd):
            return os.write(fd, data)
        if self.left <= 0:
            self.failures += 1
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = os.write(fd, bytes(data[:self.left]))
        self.left -= n
        return n


def run_cli(folder: Path, *extra: str):
    return CliRunner().invoke(app, ["run", str(TOTEM), "--virtual-time", "--yes", "--plain",
                                    "--no-report", "--log-dir", str(folder), *extra])


def assert_readable(folder: Path) -> None:
    """Whatever is on disk reads back: whole trace lines only, events that parse, no
    temporary file left."""
    text = RunFolder(folder).trace_text()
    assert text == "" or text.endswith("\n")
    assert len(read_trace(folder)) == len(text.splitlines())
    RunFolder(folder).events()   # every line parses
    assert not list(folder.glob("*.tmp")), list(folder.iterdir())


# ----------------------------------------------------------------------------- disk full
# (the last budget fills late in a faulted run: it writes ~61 kB since the events are
# compressed, the passing one ~141 kB)
@pytest.mark.parametrize("budget", [0, 3_000, 40_000, 55_000])
@pytest.mark.parametrize("fault, code", [((), 0), (("--sim-fault", "4:tow_error@3"), 3)])
def test_a_full_disk_never_disturbs_the_run(tmp_path, monkeypatch, budget, fault, code):
    """Issue: one traceback per CAN frame, exit 1 instead of 3, report.json.tmp left, a
    partial last line in trace.log. Now: one line, the run's own exit code, whole lines."""
    disk = FullDisk(budget)
    monkeypatch.setattr(logfile, "_write", disk)
    folder = tmp_path / "run"
    result = run_cli(folder, *fault)
    assert result.exit_code == code, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert "Traceback" not in result.output
    assert disk.failures >= 1, "the disk never filled up"
    warnings = [line for line in result.output.splitlines() if "run log:" in line]
    assert len(warnings) == 1, result.output      # said once, not once per frame
    assert "No space left on device" in warnings[0]
    assert ("PASSED" if code == 0 else "FAILED") in result.output
    assert_readable(folder)


@pytest.mark.parametrize("budget", [0, 2_000])
def test_a_full_disk_at_the_record_copy_is_one_line_and_nothing_moves(tmp_path, monkeypatch,
                                                                      budget):
    """Issue 23 (item 6): the record of what runs cannot be written: no run without it.
    One line, exit 2, no motion (no trace, no events), no temporary file left."""
    disk = FullDisk(budget, record=True)
    monkeypatch.setattr(logfile, "_write", disk)
    folder = tmp_path / "run"
    result = run_cli(folder)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and disk.failures >= 1
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    assert "cannot write the run record" in errors[0] and "nothing was sent" in errors[0]
    assert "No space left on device" in errors[0]
    assert not list(folder.glob("trace.log*")) and not list(folder.glob("events.jsonl*"))
    assert not list(folder.rglob("*.tmp")), list(folder.rglob("*"))


@pytest.mark.parametrize("budget", [5_000, 60_000])
def test_a_disk_filling_up_during_the_run_leaves_a_finished_report(tmp_path, monkeypatch,
                                                                   budget):
    """Issue 23 (item 6): report.json said "running" of a run that had ended, and
    report.html.tmp was left behind. The ending is written into the room the running
    report keeps; report.html fails in one line with nothing left behind."""
    disk = FullDisk(budget)
    monkeypatch.setattr(logfile, "_write", disk)
    folder = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", str(TOTEM), "--virtual-time", "--yes",
                                      "--plain", "--log-dir", str(folder)])
    assert result.exit_code == 0, result.output
    assert disk.failures >= 1, "the disk never filled up"
    report = json.loads((folder / "report.json").read_text())
    assert report["status"] == "passed" and report["exit_code"] == 0, report
    assert report["log_errors"] and "No space left on device" in report["log_errors"][0]
    assert not list(folder.rglob("*.tmp")), list(folder.rglob("*"))
    assert "report.html not written" in result.output
    assert not (folder / "report.html").exists()


def test_a_full_disk_leaves_the_arm_behaviour_unchanged(tmp_path, monkeypatch):
    """Every frame on the bus, at the same (virtual) time, with and without a full disk."""
    def frames(folder: Path) -> list[tuple]:
        loaded = load_sequence(TOTEM)
        arm = load_arm(loaded.arm_path)
        connection = open_connection(force_sim=True, clock=VirtualClock())
        seen: list[tuple] = []

        def attach(executor) -> None:
            executor.client.add_frame_listener(
                lambda m: seen.append((m.timestamp, m.arbitration_id, bytes(m.data), m.is_rx)))
        try:
            outcome = run_sequence(loaded, arm, connection, log_dir=folder,
                                   confirm=lambda p: True, on_executor=attach,
                                   html_report=False)
        finally:
            connection.close()
        assert outcome.result.exit_code == 0
        return seen

    clean = frames(tmp_path / "clean")
    monkeypatch.setattr(logfile, "_write", FullDisk(10_000))
    assert frames(tmp_path / "full") == clean


def test_a_full_disk_is_recorded_in_the_report_when_the_report_fits(tmp_path, monkeypatch):
    """The trace fills the disk; space comes back for the end (another process freed
    it): the report says which file stopped."""
    class TraceOnly(FullDisk):
        def __call__(self, fd, data):
            if os.readlink(f"/proc/self/fd/{fd}").endswith("trace.log.gz"):
                return super().__call__(fd, data)
            return os.write(fd, data)

    monkeypatch.setattr(logfile, "_write", TraceOnly(5_000))
    result = run_cli(tmp_path / "run")
    assert result.exit_code == 0
    report = RunFolder(tmp_path / "run").report()
    assert report["status"] == "passed"
    assert any("trace.log.gz" in e for e in report["log_errors"]), report.get("log_errors")
    kinds = [e["type"] for e in RunFolder(tmp_path / "run").events()]
    assert "log_failed" in kinds and kinds[-1] == "run_finished"
    assert "the run log is incomplete" in result.output


# ----------------------------------------------------------------------------- --log-dir
def digest(folder: Path) -> dict[str, str]:
    """The first run's files (top level and its inputs/), not the later runs' folders."""
    files = [p for p in folder.iterdir() if p.is_file()]
    if (folder / "inputs").is_dir():
        files += [p for p in (folder / "inputs").rglob("*") if p.is_file()]
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in files}


def test_a_reused_log_dir_keeps_the_earlier_run(tmp_path):
    """Issue: a second run with the same --log-dir overwrote the first one's evidence."""
    folder = tmp_path / "logs"
    first = run_cli(folder)
    assert first.exit_code == 0
    before = digest(folder)
    second = run_cli(folder)
    assert second.exit_code == 0, second.output
    assert digest(folder) == before                  # the first run untouched
    (inner,) = [p for p in folder.iterdir() if (p / "report.json").exists()]
    assert RunFolder(inner).report()["status"] == "passed"
    assert f"this run goes to {inner}" in second.output
    third = run_cli(folder)                          # the same second: its own folder
    assert third.exit_code == 0
    assert len([p for p in folder.iterdir() if (p / "report.json").exists()]) == 2
    assert digest(folder) == before


def test_a_refused_run_never_overwrites_an_earlier_run_in_its_log_dir(tmp_path):
    """A run refused by validation leaves its short record in a new folder too, beside the
    earlier run's evidence, for a file that loads and for one that does not."""
    folder = tmp_path / "logs"
    assert run_cli(folder).exit_code == 0
    before = digest(folder)
    sequences = tmp_path / "sequences"
    sequences.mkdir()
    invalid = sequences / "invalid.yaml"   # loads, then fails validation
    invalid.write_text("name: Bad\ndescription: x\nsteps:\n  - include: "
                       f"{TOTEM.parent / 'startup.yaml'}\n  - move: {{joints: {{j2: 150}}}}\n")
    unloadable = sequences / "unloadable.yaml"
    unloadable.write_text("name: Bad\nsteps: 3\n")
    for bad in (invalid, unloadable):
        result = CliRunner().invoke(app, ["run", str(bad), "--virtual-time", "--yes",
                                          "--plain", "--log-dir", str(folder)])
        assert result.exit_code == 1, result.output
    assert digest(folder) == before
    refused = [RunFolder(p).report() for p in folder.iterdir()
               if (p / "report.json").exists()]
    assert [r["status"] for r in refused] == ["refused", "refused"]


def test_an_empty_log_dir_is_used_as_it_is(tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    assert run_cli(folder).exit_code == 0
    assert (folder / "report.json").exists()


def test_an_unwritable_existing_log_dir_is_one_line_exit_2(tmp_path):
    """Issue: an existing read-only --log-dir gave a traceback, exit 1. /proc exists and
    takes no new files (even for root, where a chmod would not stop anything)."""
    result = CliRunner().invoke(app, ["run", str(TOTEM), "--virtual-time", "--yes",
                                      "--plain", "--log-dir", "/proc"])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert "cannot create the run folder /proc" in result.output


# ----------------------------------------------------------------------------- time base
def test_the_trace_is_on_wall_clock_time_with_one_channel_and_converts(tmp_path):
    """Issue: sent frames said vcan0, received ones seqrun-1; stamps counted from boot,
    so a conversion to .asc said 1970. Events + the start time = trace time."""
    before = time.time()
    result = run_cli(tmp_path / "run")
    after = time.time()
    assert result.exit_code == 0
    folder = tmp_path / "run"
    frames = RunFolder(folder).trace_frames()                           # python-can reads it
    assert {m.channel for m in frames} == {frames[0].channel}           # one name
    assert {m.is_rx for m in frames} == {True, False}                   # both directions
    duration = RunFolder(folder).report()["duration_s"]
    assert before - 1 <= frames[0].timestamp and frames[-1].timestamp <= after + duration + 1
    # python-can's converter writes a Vector .asc whose start is today, not 1970.
    with can.Logger(str(folder / "trace.asc")) as asc:
        for m in frames:
            asc.on_message_received(m)
    text = (folder / "trace.asc").read_text()
    triggerblock = text.split("Begin Triggerblock")[1].splitlines()[0]
    assert time.strftime("%Y") in triggerblock, triggerblock
    assert len(list(can.LogReader(str(folder / "trace.asc")))) == len(frames)
    # One time base: event t + start_epoch_s is the frame's time. Step 1 (Reset) starts
    # with the Reset broadcast; a step's first frame comes within a cycle of its event.
    events = RunFolder(folder).events()
    started = next(e for e in events if e["type"] == "run_started")
    report = RunFolder(folder).report()
    assert started["type"] == "run_started"
    assert report["start_epoch_s"] == started["start_epoch_s"]
    step1 = next(e for e in events if e["type"] == "step_started")
    reset = next(m for m in frames if m.arbitration_id == 0x100 and m.data[0] == 0x00)
    assert reset.timestamp == pytest.approx(started["start_epoch_s"] + step1["t"], abs=0.01)
    # On the run's own clock (what the executor and the simulator saw) the Reset is at
    # the event's t to the microsecond the trace keeps.
    on_run_clock = read_trace(folder, run_clock=True)
    reset_run = next(m for m in on_run_clock if m.arbitration_id == 0x100 and m.data[0] == 0)
    assert reset_run.timestamp == pytest.approx(step1["t"] + started["clock_s"], abs=2e-6)


# ----------------------------------------------------------------------------- report cost
def fake_run(folder: Path, steps: int, *, finish: bool = True) -> RunLog:
    """A run log fed with ``steps`` finished steps (events as the executor emits them)."""
    clock = VirtualClock()
    log = RunLog(folder, {"sequence": "fake"}, clock=clock, channel="can0")
    log.on_event({"t": 0.0, "type": "run_started", "steps": steps, "clock_s": 0.0})
    results = []
    for n in range(1, steps + 1):
        log.on_event({"t": n, "type": "step_started", "step": n, "kind": "wait",
                      "label": f"wait {n}", "location": f"f.yaml:{n}:3"})
        log.on_frame(can.Message(arbitration_id=0x0C1, data=b"\x0a\x3c",
                                 is_extended_id=False, timestamp=clock.now()))
        clock.sleep(0.01)
        log.on_event({"t": n + 0.01, "type": "step_finished", "step": n, "status": "passed",
                      "duration_s": 0.01, "planned_duration_s": None})
        results.append(StepResult(n, "wait", f"wait {n}", f"f.yaml:{n}:3", "passed", n, n + 0.01))
    if finish:
        log.finish(RunResult("passed", 0, "sequence completed", results, 0.0, steps + 0.01))
        log.close()
    return log


def test_the_per_step_cost_of_the_report_is_constant(tmp_path, monkeypatch):
    """Issue: report.json rewritten whole after every step, O(n²). Bytes written while
    running grow linearly with the steps (the final report aside)."""
    written: dict[int, int] = {}
    for steps in (100, 1000):
        count = [0]

        def write(fd, data, count=count):
            count[0] += len(data)
            return os.write(fd, data)

        monkeypatch.setattr(logfile, "_write", write)
        fake_run(tmp_path / str(steps), steps, finish=False).close()
        written[steps] = count[0]
    assert written[1000] / written[100] < 11, written


def test_a_killed_run_reads_back_with_its_steps(tmp_path):
    """A run killed after 30 steps: report.json says running; read_report adds the steps
    from steps.jsonl (a partly written last line is ignored)."""
    folder = tmp_path / "run"
    log = fake_run(folder, 30, finish=False)
    log.close()
    with open(folder / "steps.jsonl", "a") as f:
        f.write('{"number": 31, "sta')                   # the line being written
    raw = RunFolder(folder).report()
    assert raw["status"] == "running" and raw["steps_file"] == "steps.jsonl"
    report = read_report(folder)
    assert [s["number"] for s in report["steps"]] == list(range(1, 31))
    assert report["steps"][0]["label"] == "wait 1" and report["steps"][0]["status"] == "passed"
    assert report["last_event"]["type"] == "step_finished"


def test_a_finished_run_reads_back_whole(tmp_path):
    fake_run(tmp_path / "run", 5)
    report = read_report(tmp_path / "run")
    assert report["status"] == "passed" and len(report["steps"]) == 5
    assert report == RunFolder(tmp_path / "run").report()


# ----------------------------------------------------------------------------- compressed trace
def frame_at(clock: VirtualClock, n: int) -> can.Message:
    return can.Message(arbitration_id=0x0C0 + n % 7 + 1, data=bytes([0x0A, 0x3C, n % 256]),
                       is_extended_id=False, timestamp=clock.now())


def test_a_killed_run_leaves_its_trace_up_to_its_last_event(tmp_path):
    """The trace is compressed; a run killed (nothing closed, no gzip trailer) leaves
    every frame before its last event other than a reading, and whole lines only."""
    clock = VirtualClock()
    log = RunLog(tmp_path / "run", {"sequence": "killed"}, clock=clock, channel="can0")
    log.on_event({"t": 0.0, "type": "run_started", "clock_s": 0.0})
    for n in range(40):
        log.on_frame(frame_at(clock, n))
        clock.sleep(0.001)
    log.on_event({"t": clock.now(), "type": "step_started", "step": 1, "kind": "wait",
                  "label": "wait", "location": "f.yaml:1:3"})
    for n in range(3):   # within the flush interval of the last flush: may be lost
        log.on_frame(frame_at(clock, 100 + n))
    # SIGKILL here: nothing is closed. What is on disk decodes to whole lines.
    path = tmp_path / "run" / "trace.log.gz"
    assert path.is_file() and not (tmp_path / "run" / "trace.log").exists()
    frames = read_trace(tmp_path / "run")
    assert 40 <= len(frames) <= 43
    assert [m.data[2] for m in frames[:40]] == list(range(40))
    assert RunFolder(tmp_path / "run").trace_text().endswith("\n")
    log.close()
    assert len(RunFolder(tmp_path / "run").trace_frames()) == 43   # closed: python-can reads all


def test_a_killed_run_loses_at_most_the_flush_interval_of_its_trace(tmp_path):
    # A long move streams readings only (no other event): frames at 100 Hz for 2 s.
    clock = VirtualClock()
    log = RunLog(tmp_path / "run", {"sequence": "killed"}, clock=clock, channel="can0")
    log.on_event({"t": 0.0, "type": "run_started", "clock_s": 0.0})
    for n in range(200):
        log.on_frame(frame_at(clock, n))
        log.on_event({"t": clock.now(), "type": "setpoint", "step": 1})
        clock.sleep(0.01)
    frames = read_trace(tmp_path / "run", run_clock=True)
    assert frames and frames[-1].timestamp >= clock.now() - 0.01 - TRACE_FLUSH_S - 1e-6
    assert [m.data[2] for m in frames] == list(range(len(frames)))
    log.close()


def test_an_uncompressed_trace_of_an_older_run_still_reads(tmp_path):
    """Run folders of earlier versions hold trace.log: seqrun report, the CSV export
    and the trace readers take it as they take trace.log.gz."""
    new = tmp_path / "new"
    assert run_cli(new).exit_code == 0
    old = tmp_path / "old"
    shutil.copytree(new, old)
    (old / "trace.log").write_bytes(gzip.decompress((old / "trace.log.gz").read_bytes()))
    (old / "trace.log.gz").unlink()
    def frames(folder: Path) -> list[tuple]:
        return [(m.timestamp, m.arbitration_id, bytes(m.data), m.is_rx, m.channel)
                for m in read_trace(folder)]

    assert frames(old) == frames(new) and len(frames(old)) > 100
    assert RunFolder(old).trace_lines() == RunFolder(new).trace_lines()
    for folder in (old, new):
        result = CliRunner().invoke(app, ["report", str(folder), "--csv", str(folder / "csv"),
                                          "--out", str(folder / "report.html")])
        assert result.exit_code == 0, result.output
    sent = len([m for m in read_trace(new) if not m.is_rx])
    for folder in (old, new):
        assert f"{sent} frames sent" in (folder / "report.html").read_text()
    assert (old / "csv" / "timeseries.csv").read_bytes() == \
        (new / "csv" / "timeseries.csv").read_bytes()


def test_the_trace_is_compressed_a_block_at_a_time(tmp_path, monkeypatch):
    """Issue 42.8: python-can's writer hands the trace one frame at a time, and each line
    was compressed by itself (one zlib call per CAN frame: most of the trace's CPU). The
    lines now wait for the next flush and are compressed together; the file is still one
    gzip stream that python-can's LogReader and zcat read whole."""
    import subprocess
    import types
    import zlib

    calls: dict[int, int] = {}   # compressor (one per file: trace, events) -> calls

    class Counted:
        def __init__(self, *args: int) -> None:
            self._z = zlib.compressobj(*args)

        def compress(self, data: bytes) -> bytes:
            calls[id(self)] = calls.get(id(self), 0) + 1
            return self._z.compress(data)

        def flush(self, mode: int = zlib.Z_FINISH) -> bytes:
            return self._z.flush(mode)

    monkeypatch.setattr(logfile, "zlib", types.SimpleNamespace(
        compressobj=Counted, DEFLATED=zlib.DEFLATED, MAX_WBITS=zlib.MAX_WBITS,
        Z_SYNC_FLUSH=zlib.Z_SYNC_FLUSH, Z_FINISH=zlib.Z_FINISH, error=zlib.error))
    clock = VirtualClock()
    log = RunLog(tmp_path / "run", {"sequence": "blocks"}, clock=clock, channel="can0")
    log.on_event({"t": 0.0, "type": "run_started", "clock_s": 0.0})
    frames = 0
    for cycle in range(200):              # 2 s at 100 Hz, 14 frames a cycle
        for n in range(14):
            log.on_frame(frame_at(clock, frames))
            frames += 1
        log.on_event({"t": clock.now(), "type": "setpoint", "step": 1})
        clock.sleep(0.01)
    log.close()
    flushes = 2.0 / TRACE_FLUSH_S
    assert len(calls) == 2 and 0 < max(calls.values()) <= flushes + 3, (calls, frames)
    path = tmp_path / "run" / "trace.log.gz"
    text = subprocess.run(["gzip", "-dc", str(path)], capture_output=True, check=True).stdout
    assert text.decode() == RunFolder(tmp_path / "run").trace_text()
    assert len(text.splitlines()) == frames
    read = list(can.LogReader(str(path)))                   # python-can reads the .gz itself
    assert [m.data[2] for m in read] == [n % 256 for n in range(frames)]


def test_a_block_of_the_trace_bigger_than_its_bound_goes_to_the_compressor(tmp_path):
    """The lines held between two flushes are bounded in memory: a caller that never
    flushes still gets a whole, readable file at close."""
    trace = logfile.GzipLineFile(tmp_path / "t.log.gz", lambda path, exc: None)
    line = "(1.000000) can0 0C1#0A3C R\n"
    count = 3 * logfile.GzipLineFile.BLOCK_BYTES // len(line)
    for _ in range(count):
        assert trace.write(line)
    assert (tmp_path / "t.log.gz").stat().st_size > 0       # went out before any flush
    trace.close()
    assert gzip.decompress((tmp_path / "t.log.gz").read_bytes()).decode() == line * count


# ----------------------------------------------------------------------------- compressed events
def test_the_events_are_compressed_and_every_reader_takes_them(tmp_path):
    """Issue 41.3: events.jsonl took ~97 MB per hour of motion (the 100 Hz readings). It
    is written gzip-compressed as events.jsonl.gz (zcat reads it), and what reads a run
    folder (report, runs, run.mcap's rebuild) takes it as it takes an older events.jsonl."""
    import subprocess

    folder = tmp_path / "run"
    assert run_cli(folder).exit_code == 0
    path = folder / "events.jsonl.gz"
    assert path.is_file() and not (folder / "events.jsonl").exists()
    text = subprocess.run(["gzip", "-dc", str(path)], capture_output=True, check=True).stdout
    assert path.stat().st_size * 4 < len(text)
    events = [json.loads(line) for line in text.splitlines()]
    assert events == RunFolder(folder).events() and events[-1]["type"] == "run_finished"
    assert len([e for e in events if e["type"] == "setpoint"]) > 300
    result = CliRunner().invoke(app, ["report", str(folder), "--out", str(folder / "r.html")])
    assert result.exit_code == 0, result.output
    result = CliRunner().invoke(app, ["runs", "--dir", str(tmp_path)])
    assert result.exit_code == 0 and "passed" in result.output, result.output


def test_a_killed_run_keeps_every_event_but_its_last_readings(tmp_path):
    """Nothing closed (SIGKILL): every event other than a reading is on disk as it was
    written, the readings at most TRACE_FLUSH_S behind."""
    clock = VirtualClock()
    folder = tmp_path / "run"
    log = RunLog(folder, {"sequence": "killed"}, clock=clock, channel="can0")
    log.on_event({"t": 0.0, "type": "run_started", "clock_s": 0.0})
    for n in range(100):
        log.on_event({"t": round(n * 0.01, 6), "type": "setpoint", "step": 1, "k": n})
    log.on_event({"t": 1.0, "type": "fault", "cause": "following_error", "step": 1})
    for n in range(3):
        log.on_event({"t": 1.0 + n * 0.01, "type": "setpoint", "step": 1, "k": 100 + n})
    events = read_report_events(folder)
    kinds = [e["type"] for e in events]
    assert kinds[0] == "run_started" and "fault" in kinds
    assert [e["k"] for e in events if "k" in e][:100] == list(range(100))
    log.close()
    assert len(read_report_events(folder)) == 105


def read_report_events(folder: Path) -> list[dict]:
    from seqrun.service.runlog import read_events

    return read_events(folder)
