"""The operator console: STOP latency, telemetry rate with three tabs, idle CPU.

1. **STOP click -> Halt frame on the wire**, over ``--clicks`` (100) presses of the page's
   STOP button in Chromium (the arm is reset between presses). The press time is the
   browser's event time (``performance.timeOrigin + event.timeStamp`` of the pointerdown);
   the Halt time is when the session handed the Halt broadcast to the bus (wall clock, same
   machine). Goal: p99 < 20 ms.
2. **The 100 Hz loop with three tabs vs with no page**, from one run of this script: a
   ``seqrun console --sim`` process (as a facility runs it: the browser and this script
   share nothing with its interpreter) runs ``sequences/opsafe.yaml`` ``--repeats`` times
   per mode, the modes alternating run by run (the order turns round every repetition):
   ``none`` (no page open), ``tabs`` (three tabs of the page), and for experiments
   ``tabs-nodraw`` (three tabs that receive and count but paint nothing: ``?draw=0``). Per
   mode: the loop's period (spacing of the run's ``setpoint`` events) p50/p99/max pooled
   and p99 per run; status messages each tab received per second while the arm moved; the
   CPU of the console process and of Chromium. Goals: >= 50 Hz in every tab; the loop's p99
   with three tabs as without. ``--rt-priority N`` runs the console with ``--rt-priority
   N`` (its loop thread at SCHED_FIFO; needs root or CAP_SYS_NICE): say so beside a figure.
   Experiments: ``--switch-interval S`` (the console interpreter's GIL switch interval),
   ``--browser-cpus LIST`` (Chromium under ``taskset -c LIST``).
3. **Idle CPU** of a ``seqrun console --sim`` process (user + system time over
   ``--idle-seconds``), with no page and with one tab open.

Chromium: /usr/bin/chromium or $SEQRUN_CHROMIUM (Playwright drives it; no browser download).

Run: ``.venv/bin/python bench/bench_console.py [--clicks 100] [--idle-seconds 10]
[--repeats 3] [--modes none,tabs] [--rt-priority N] [--skip stop|telemetry|idle]``
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from bench_liveview import event_periods, summary  # noqa: E402
from consolekit import LiveServer, console_setup, wait_for  # noqa: E402
from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

from seqrun.service.realtime import (  # noqa: E402
    keep_long_lived_objects_out_of_collections,
    use_round_robin,
)
from seqrun.service.session import ArmSession  # noqa: E402

CHROMIUM = os.environ.get("SEQRUN_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader", "--disable-background-networking",
        "--disable-component-update", "--no-first-run",
        # three tabs in one window: background tabs must not be throttled for the count
        "--disable-background-timer-throttling", "--disable-renderer-backgrounding",
        "--disable-backgrounding-occluded-windows"]
READY = ("window.seqrunConsole && window.seqrunConsole.ready "
         "&& window.seqrunConsole.statusCount > 1")


def pct(values: list[float]) -> dict:
    a = np.array(values)
    return {"n": len(a), "p50_ms": round(float(np.percentile(a, 50)), 2),
            "p99_ms": round(float(np.percentile(a, 99)), 2), "max_ms": round(float(a.max()), 2)}


def open_page(browser, url: str):
    page = browser.new_context(viewport={"width": 1400, "height": 950}).new_page()
    page.goto(url)
    page.wait_for_function(READY, timeout=30000)
    return page


def normal_scheduling() -> None:
    """Every thread of this process back at SCHED_OTHER (after the STOP section)."""
    for task in Path("/proc/self/task").iterdir():
        try:
            os.sched_setscheduler(int(task.name), os.SCHED_OTHER, os.sched_param(0))
        except (ProcessLookupError, PermissionError):
            pass


class TimedSession(ArmSession):
    """The arm session, noting when each halt() call began (wall clock): the STOP latency
    splits into the page-to-server part and the session's own."""

    halt_calls: list[float]

    def halt(self, reason: str = "STOP"):
        self.halt_calls.append(time.time())
        return super().halt(reason)


def stop_latency(browser, setup, server, clicks: int) -> dict:
    page = open_page(browser, server.url)
    setup.session.arm_up()
    setup.session.home()
    latencies, to_server, in_session = [], [], []
    for _ in range(clicks):
        setup.session.reset()
        pressed_before = page.evaluate("window.seqrunConsole.stopTimes.length")
        start = time.time()
        page.click("#stop")
        halt = wait_for(lambda: setup.wire.halts_epoch(start), timeout=5)[0]
        called = [t for t in setup.session.halt_calls if t >= start][0]
        pressed = page.evaluate(f"window.seqrunConsole.stopTimes[{pressed_before}]") / 1000
        latencies.append((halt - pressed) * 1000)
        to_server.append((called - pressed) * 1000)
        in_session.append((halt - called) * 1000)
        wait_for(lambda: setup.session.status().activity == "halted", timeout=5)
    page.context.close()
    setup.session.reset()
    return {**pct(latencies), "press_to_halt_call": pct(to_server),
            "halt_call_to_frame": pct(in_session)}


# -- section 2: the 100 Hz loop with and without three tabs, alternating (a console process)
class ConsoleProcess:
    """``seqrun console --sim --port 0`` in its own process, as a facility runs it (the
    browsers and this script's Playwright client share nothing with its interpreter)."""

    def __init__(self, log_dir: Path, *, rt_priority: int | None = None,
                 switch_interval: float | None = None, nice: int | None = None,
                 prefix: str | None = None) -> None:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        args = ["console", "--sim", "--port", "0", "--yes", "--log-dir", str(log_dir)]
        if rt_priority is not None:
            args += ["--rt-priority", str(rt_priority)]
        if switch_interval is None:
            command = [sys.executable, "-m", "seqrun", *args]
        else:  # an experiment: the interpreter's GIL switch interval
            command = [sys.executable, "-c",
                       f"import sys; sys.setswitchinterval({switch_interval}); "
                       f"sys.argv = ['seqrun'] + {args!r}; "
                       "from seqrun.entry import main; main()"]
        if nice is not None:  # an experiment: the whole process (every thread) at nice N
            command = ["nice", "-n", str(nice), *command]
        if prefix:  # an experiment: e.g. "chrt -r 1" (every thread of the process)
            command = [*prefix.split(), *command]
        self.log_dir = log_dir
        self.proc = subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        self.url = ""
        self.lines: list[str] = []
        self.answered: set[str] = set()  # confirm questions answered (ids are per session)
        while not self.url:
            line = self.proc.stdout.readline()
            if not line:
                raise RuntimeError("seqrun console ended before printing its URL:\n"
                                   + "".join(self.lines))
            self.lines.append(line)
            found = re.search(r"(http://\S+)", line)
            self.url = found.group(1) if found else ""
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)

    def call(self, method: str, path: str, body: dict | None = None) -> Any:
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.url.rstrip("/") + "/api/v1" + path, data=data,
                                         method=method,
                                         headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=60) as response:
            return json.loads(response.read())

    def close(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def task_times(pid: int) -> dict[int, tuple[float, float]]:
    """Per thread of ``pid``: (CPU seconds, seconds waited for a CPU while runnable)."""
    out = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            on_cpu, waited, _ = (Path(task) / "schedstat").read_text().split()
        except (OSError, ValueError):
            continue
        out[int(task.name)] = (int(on_cpu) / 1e9, int(waited) / 1e9)
    return out


def answer_questions(console: ConsoleProcess, answered: set[str]) -> set[str]:
    asked = [e["question_id"] for e in console.call("GET", "/events")
             if e["type"] == "confirm_requested" and e["question_id"] not in answered]
    for question in asked:
        try:
            console.call("POST", "/answer", {"question_id": question, "yes": True})
        except urllib.error.HTTPError as exc:  # 409: closed meanwhile (the run ended)
            if exc.code != 409:
                raise
    return set(asked)


def browser_cpu_seconds() -> float:
    """CPU seconds used so far by the browser's processes (Chromium, children of this one's
    Playwright driver)."""
    parents, names, cpu = {}, {}, {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            head, tail = (entry / "stat").read_text().rsplit(")", 1)
        except OSError:
            continue
        fields = tail.split()
        pid = int(entry.name)
        parents[pid], names[pid] = int(fields[1]), head.split("(", 1)[1]
        cpu[pid] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def ours(pid: int) -> bool:
        while pid > 1:
            pid = parents.get(pid, 0)
            if pid == os.getpid():
                return True
        return False

    return sum(c for pid, c in cpu.items() if "chrom" in names[pid] and ours(pid))


def one_run(console: ConsoleProcess, browser, tabs: int, page_url: str) -> dict:
    """One run of opsafe with ``tabs`` pages open: the loop's periods, each tab's rate, and
    how much CPU time the console process' threads got and waited for."""
    pages = [open_page(browser, page_url) for _ in range(tabs)]
    before = task_times(console.proc.pid)
    browser_before = browser_cpu_seconds()
    console.call("POST", "/run", {"sequence": "opsafe.yaml"})
    rates: list[list[float]] = [[] for _ in pages]
    counts = [p.evaluate("window.seqrunConsole.statusCount") for p in pages]
    last = time.perf_counter()
    started = time.monotonic()
    answered = console.answered
    while True:
        for _ in range(4):  # opsafe's confirm steps: yes (as seqrun run --yes)
            time.sleep(0.25)
            answered |= answer_questions(console, answered)
        now = time.perf_counter()
        activity = console.call("GET", "/status")["activity"]
        new = [p.evaluate("window.seqrunConsole.statusCount") for p in pages]
        if activity == "running":
            for k in range(len(pages)):
                rates[k].append((new[k] - counts[k]) / (now - last))
        counts, last = new, now
        if activity not in ("running", "paused") or time.monotonic() - started > 300:
            break
    seconds = time.monotonic() - started
    after = task_times(console.proc.pid)
    browser_cpu = max(0.0, browser_cpu_seconds() - browser_before)  # (closed tabs: gone)
    for p in pages:
        p.context.close()
    newest = console.call("GET", "/runs")[0]
    periods = event_periods(console.log_dir / newest["id"])
    cpu = sum(after[t][0] - before.get(t, (0, 0))[0] for t in after)
    waited = sum(after[t][1] - before.get(t, (0, 0))[1] for t in after)
    if newest.get("result") != "passed":
        print(f"   (run {newest['id']}: {newest.get('result')}; "
              f"{console.call('GET', '/events')[-3:]})")
    return {"result": newest.get("result"), "periods": periods,
            "rates": [float(np.median(r)) if r else None for r in rates],
            "min_rates": [float(np.min(r)) if r else None for r in rates],
            "cpu_percent": round(100 * cpu / seconds, 1),
            "browser_cpu_percent": round(100 * browser_cpu / seconds, 1),
            "runnable_wait_ms_per_s": round(1000 * waited / seconds, 1)}


def loop_ab(browser, repeats: int, modes: list[str], *, rt_priority: int | None = None,
            switch_interval: float | None = None, nice: int | None = None,
            prefix: str | None = None) -> dict:
    """The loop's period during opsafe, the modes alternating run by run (the order turns
    round every repetition): ``none`` no page, ``tabs`` three tabs of the page,
    ``tabs-nodraw`` three tabs of the page with ``?draw=0`` (messages counted, nothing
    drawn: isolates what drawing costs)."""
    runs: dict[str, list[dict]] = {m: [] for m in modes}
    with tempfile.TemporaryDirectory() as tmp:
        console = ConsoleProcess(Path(tmp), rt_priority=rt_priority,
                                 switch_interval=switch_interval, nice=nice, prefix=prefix)
        try:
            for rep in range(repeats):
                for mode in (modes if rep % 2 == 0 else modes[::-1]):
                    url = console.url + ("?draw=0" if mode == "tabs-nodraw" else "")
                    run = one_run(console, browser, 0 if mode == "none" else 3, url)
                    s = summary(run["periods"])
                    runs[mode].append(run)
                    print(f"   {mode:12s} rep {rep + 1}: {run['result']}, loop p50 "
                          f"{s.get('p50_ms')} ms p99 {s.get('p99_ms')} ms max "
                          f"{s.get('max_ms')} ms; tabs "
                          f"{[round(r or 0, 1) for r in run['rates']]} Hz; console CPU "
                          f"{run['cpu_percent']} %, Chromium CPU "
                          f"{run['browser_cpu_percent']} %, console threads waited for a CPU "
                          f"{run['runnable_wait_ms_per_s']} ms/s", flush=True)
        finally:
            console.close()
    out = {}
    for mode, items in runs.items():
        rates = [r for run in items for r in run["rates"] if r is not None]
        out[mode] = {"loop": summary([p for run in items for p in run["periods"]]),
                     "loop_p99_per_run_ms": [summary(run["periods"]).get("p99_ms")
                                             for run in items],
                     "tab_median_hz": round(float(np.median(rates)), 1) if rates else None,
                     "tab_min_hz": round(float(min(rates)), 1) if rates else None,
                     "console_cpu_percent": [run["cpu_percent"] for run in items],
                     "browser_cpu_percent": [run["browser_cpu_percent"] for run in items],
                     "runnable_wait_ms_per_s": [run["runnable_wait_ms_per_s"]
                                                for run in items],
                     "results": [run["result"] for run in items]}
    return out


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def idle_cpu(browser, seconds: float) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.Popen([sys.executable, "-m", "seqrun", "console", "--sim", "--port",
                                 "0", "--log-dir", tmp], cwd=ROOT, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            url = None
            while url is None:
                line = proc.stdout.readline()
                if not line:
                    raise RuntimeError("seqrun console ended before printing its URL")
                found = re.search(r"(http://\S+)", line)
                url = found.group(1) if found else None
            out = {}
            for label, tabs in (("no_page", 0), ("one_tab", 1)):
                pages = [open_page(browser, url) for _ in range(tabs)]
                time.sleep(2.0)
                c0, t0 = cpu_seconds(proc.pid), time.perf_counter()
                time.sleep(seconds)
                used = cpu_seconds(proc.pid) - c0
                out[label] = {"cpu_percent": round(100 * used / (time.perf_counter() - t0), 2)}
                for p in pages:
                    p.context.close()
            return out
        finally:
            proc.terminate()
            proc.wait(timeout=20)


def launch(pw, browser_cpus: str | None):
    executable = CHROMIUM
    if browser_cpus:  # an experiment: the browser's processes on these CPUs only
        wrapper = Path(tempfile.mkdtemp()) / "chromium"
        wrapper.write_text(f'#!/bin/sh\nexec taskset -c {browser_cpus} {CHROMIUM} "$@"\n')
        wrapper.chmod(0o755)
        executable = str(wrapper)
    return pw.chromium.launch(executable_path=executable, headless=True, args=ARGS)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--clicks", type=int, default=100)
    parser.add_argument("--idle-seconds", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=3,
                        help="runs of opsafe per mode for the loop's period (alternating)")
    parser.add_argument("--modes", default="none,tabs",
                        help="comma-separated: none, tabs, tabs-nodraw")
    parser.add_argument("--rt-priority", type=int, metavar="N",
                        help="seqrun console --rt-priority N for the loop's runs")
    parser.add_argument("--switch-interval", type=float, metavar="S",
                        help="experiment: the console interpreter's sys.setswitchinterval")
    parser.add_argument("--console-nice", type=int, metavar="N",
                        help="experiment: run the console process under nice -n N")
    parser.add_argument("--console-prefix", metavar="COMMAND",
                        help='experiment: run the console under COMMAND, e.g. "chrt -r 1"')
    parser.add_argument("--browser-cpus", metavar="LIST",
                        help="experiment: run Chromium under taskset -c LIST")
    parser.add_argument("--skip", action="append", default=[],
                        choices=["stop", "telemetry", "idle"])
    parser.add_argument("--out", type=Path, default=RESULTS / "console.json")
    opts = parser.parse_args()
    from playwright.sync_api import sync_playwright

    results: dict = {"machine": machine(),
                     "command": " ".join(["python", "bench/bench_console.py", *sys.argv[1:]])}
    with sync_playwright() as pw:
        browser = launch(pw, opts.browser_cpus)
        if "stop" not in opts.skip:
            with tempfile.TemporaryDirectory() as tmp:
                TimedSession.halt_calls = []
                setup = console_setup(Path(tmp), session_class=TimedSession)
                try:
                    # as `seqrun console [--rt-priority N]` does before it serves: its
                    # threads at SCHED_RR 1, above the browser (launched before this)
                    if opts.rt_priority and use_round_robin() is not None:
                        sys.exit("--rt-priority: no right to real-time scheduling here")
                    with LiveServer(setup.app()) as server:
                        keep_long_lived_objects_out_of_collections()
                        results["stop_to_halt_frame"] = r = stop_latency(browser, setup, server,
                                                                         opts.clicks)
                finally:
                    setup.close()
                    normal_scheduling()  # the rest of the benchmark as before
            print(f"1. STOP press -> Halt frame on the wire, {r['n']} presses: p50 "
                  f"{r['p50_ms']} ms, p99 {r['p99_ms']} ms, max {r['max_ms']} ms "
                  f"(goal p99 < 20 ms)")
            for key, label in (("press_to_halt_call", "press -> session.halt()"),
                               ("halt_call_to_frame", "session.halt() -> frame")):
                part = r[key]
                print(f"   {label}: p50 {part['p50_ms']} ms, p99 {part['p99_ms']} ms, "
                      f"max {part['max_ms']} ms")
        if "telemetry" not in opts.skip:
            modes = [m.strip() for m in opts.modes.split(",") if m.strip()]
            rt = (f", the loop at SCHED_FIFO {opts.rt_priority} (--rt-priority)"
                  if opts.rt_priority else ", normal scheduling")
            rt += "".join(f", {label} {value}" for label, value in (
                ("switch interval", opts.switch_interval), ("console nice", opts.console_nice),
                ("console under", opts.console_prefix),
                ("Chromium on CPUs", opts.browser_cpus)) if value is not None)
            print(f"2. the 100 Hz loop during opsafe, {' / '.join(modes)} alternating, "
                  f"{opts.repeats} runs each{rt}:")
            t = loop_ab(browser, opts.repeats, modes, rt_priority=opts.rt_priority,
                        switch_interval=opts.switch_interval, nice=opts.console_nice,
                        prefix=opts.console_prefix)
            results["telemetry"] = {"rt_priority": opts.rt_priority,
                                    "switch_interval": opts.switch_interval,
                                    "console_nice": opts.console_nice,
                                    "console_prefix": opts.console_prefix,
                                    "browser_cpus": opts.browser_cpus, "modes": t}
            print(f"   {'mode':12s} {'cycles':>6s} {'p50 ms':>7s} {'p99 ms':>7s} "
                  f"{'max ms':>7s} {'p99 per run':>22s} {'tab Hz':>7s} {'min Hz':>7s}")
            for mode, row in t.items():
                s = row["loop"]
                per_run = " ".join(f"{x:.1f}" for x in row["loop_p99_per_run_ms"] if x)
                print(f"   {mode:12s} {s.get('cycles', 0):6d} {s.get('p50_ms', 0):7.2f} "
                      f"{s.get('p99_ms', 0):7.2f} {s.get('max_ms', 0):7.2f} {per_run:>22s} "
                      f"{row['tab_median_hz'] or '-':>7} {row['tab_min_hz'] or '-':>7}")
            print("   goals: >= 50 Hz in every tab; the loop's p99 with three tabs as without")
        if "idle" not in opts.skip:
            results["idle_cpu"] = idle = idle_cpu(browser, opts.idle_seconds)
            print(f"3. seqrun console --sim at idle: {idle['no_page']['cpu_percent']} % CPU "
                  f"with no page, {idle['one_tab']['cpu_percent']} % with one tab open")
        browser.close()
    write_json(opts.out, results)
    print(f"-> {opts.out}")


if __name__ == "__main__":
    main()
