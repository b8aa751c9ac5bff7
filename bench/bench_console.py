"""The operator console: STOP latency, telemetry rate with three tabs, idle CPU.

1. **STOP click -> Halt frame on the wire**, over ``--clicks`` (100) presses of the page's
   STOP button in Chromium (the arm is reset between presses). The press time is the
   browser's event time (``performance.timeOrigin + event.timeStamp`` of the pointerdown);
   the Halt time is when the session handed the Halt broadcast to the bus (wall clock, same
   machine). Goal: p99 < 20 ms. Then the modules' HALTED read back (the session's
   ``halt_confirmed``) -> the page's badge showing "halted". Goal: < 100 ms.
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
4. **The dry-run check hammered** (issue 24.3): the loop's period during opsafe, quiet vs
   four clients asking for opsafe's check back to back (as a web page's ``<img>`` loop
   did), alternating run by run; with ``--baseline DIR`` (the tree before issue 24, e.g.
   ``git archive 2bfba80 | tar -x -C DIR``) the same on a console of that tree in the same
   run, side by side: there the check ran in the console's process (GET, no limit), here in
   a worker process at nice 10, rate-limited.
5. **Live clients** (issue 24.4): the loop's period during opsafe with no live client vs
   ``--clients 50,50`` (50 that read every message, 50 that connect and never read; in a
   process of their own at nice 10: they stand for tablets elsewhere), alternating run by
   run in one console process. Goal: p99 within 2 ms of none.

Chromium: /usr/bin/chromium or $SEQRUN_CHROMIUM (Playwright drives it; no browser download).

Run: ``.venv/bin/python bench/bench_console.py [--clicks 100] [--idle-seconds 10]
[--repeats 3] [--modes none,tabs] [--rt-priority N] [--skip|--only
stop|telemetry|idle|check|clients] [--baseline DIR] [--clients 50,50] [--out FILE]``
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


#: Epoch ms at which the page's activity badge showed each text (a MutationObserver).
BADGE_TIMES = """() => {
  window.__badge = [];
  new MutationObserver(() => window.__badge.push([
      document.querySelector('#activity').textContent,
      performance.timeOrigin + performance.now()]))
    .observe(document.querySelector('#activity'),
             { subtree: true, childList: true, characterData: true });
}"""


def stop_latency(browser, setup, server, clicks: int) -> dict:
    """Per press: press -> Halt frame (and its two parts), and the modules' HALTED read back
    -> the page's badge "halted" (docs/console.md: within 100 ms)."""
    page = open_page(browser, server.url)
    setup.session.arm_up()
    setup.session.home()
    read_back: list[float] = []
    setup.session.events.add_listener(  # (at idle the session's own event says it)
        lambda e: read_back.append(time.time()) if e.type == "halt_confirmed" or (
            e.type == "session_halt" and e.halt_confirmed) else None, "read-back clock")
    page.evaluate(BADGE_TIMES)
    latencies, to_server, in_session, to_badge = [], [], [], []
    for _ in range(clicks):
        setup.session.reset()
        page.wait_for_function("document.querySelector('#activity').textContent !== 'halted'")
        pressed_before = page.evaluate("window.seqrunConsole.stopTimes.length")
        badges_before = page.evaluate("window.__badge.length")
        start = time.time()
        page.click("#stop")
        halt = wait_for(lambda: setup.wire.halts_epoch(start), timeout=5)[0]
        called = [t for t in setup.session.halt_calls if t >= start][0]
        pressed = page.evaluate(f"window.seqrunConsole.stopTimes[{pressed_before}]") / 1000
        latencies.append((halt - pressed) * 1000)
        to_server.append((called - pressed) * 1000)
        in_session.append((halt - called) * 1000)
        wait_for(lambda: setup.session.status().activity == "halted", timeout=5)
        page.wait_for_function("document.querySelector('#activity').textContent === 'halted'",
                               timeout=5000)
        shown = next(t for text, t in page.evaluate(f"window.__badge.slice({badges_before})")
                     if text == "halted") / 1000
        confirmed = wait_for(lambda: [t for t in read_back if t >= start], timeout=5)[0]
        to_badge.append((shown - confirmed) * 1000)
    page.context.close()
    setup.session.reset()
    return {**pct(latencies), "press_to_halt_call": pct(to_server),
            "halt_call_to_frame": pct(in_session), "read_back_to_badge": pct(to_badge)}


# -- section 2: the 100 Hz loop with and without three tabs, alternating (a console process)
class ConsoleProcess:
    """``seqrun console --sim --port 0`` in its own process, as a facility runs it (the
    browsers and this script's Playwright client share nothing with its interpreter)."""

    def __init__(self, log_dir: Path, *, rt_priority: int | None = None,
                 switch_interval: float | None = None, nice: int | None = None,
                 prefix: str | None = None, root: Path = ROOT) -> None:
        env = {**os.environ, "PYTHONPATH": str(root)}
        args = ["console", "--sim", "--port", "0", "--yes", "--log-dir", str(log_dir)]
        if rt_priority is not None:
            args += ["--rt-priority", str(rt_priority)]
        if switch_interval is None:
            command = [sys.executable, "-m", "seqrun", *args]
        else:  # an experiment: the interpreter's GIL switch interval
            command = [sys.executable, "-c",
                       f"import sys; sys.setswitchinterval({switch_interval}); "
                       f"sys.argv = ['seqrun'] + {args!r}; "
                       "from seqrun.__main__ import main; main()"]
        if nice is not None:  # an experiment: the whole process (every thread) at nice N
            command = ["nice", "-n", str(nice), *command]
        if prefix:  # an experiment: e.g. "chrt -r 1" (every thread of the process)
            command = [*prefix.split(), *command]
        self.log_dir = log_dir
        self.proc = subprocess.Popen(command, cwd=root, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        self.url = ""
        self.token: str | None = None
        self.client: str | None = None
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
        # The console prints its token in the URL (every request but STOP needs it) and
        # commands need control: this script takes it (the tabs it opens watch).
        found = re.search(r"[?&]token=([^&\s]+)", self.url)
        self.base = self.url.split("?", 1)[0]
        if found:
            self.token = found.group(1)
            self.client = self.call("POST", "/control/take", {"name": "bench"})["token"]

    def _drain(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)

    def headers(self) -> dict[str, str]:
        headers = {"Content-Type": "application/json"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        if self.client:
            headers["X-Seqrun-Control"] = self.client
        return headers

    def call(self, method: str, path: str, body: dict | None = None) -> Any:
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.base.rstrip("/") + "/api/v1" + path, data=data,
                                         method=method, headers=self.headers())
        with urllib.request.urlopen(request, timeout=60) as response:
            return json.loads(response.read())

    @property
    def live_url(self) -> str:
        """The live WebSocket's URL (with the token where the console has one)."""
        url = self.base.replace("http://", "ws://").rstrip("/") + "/api/v1/live"
        return url + (f"?token={self.token}" if self.token else "")

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


def one_run(console: ConsoleProcess, browser, tabs: int, page_url: str,
            load: Any = None) -> dict:
    """One run of opsafe with ``tabs`` pages open (and ``load`` started before it, stopped
    after it: an object with start() and stop() -> dict): the loop's periods, each tab's
    rate, and how much CPU time the console process' threads got and waited for."""
    if console.call("GET", "/status")["activity"] in ("halted", "faulted"):
        console.call("POST", "/reset")  # the run before failed (a loaded host): start again
    pages = [open_page(browser, page_url) for _ in range(tabs)]
    if load is not None:
        load.start()
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
    load_figures = load.stop() if load is not None else None
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
            "runnable_wait_ms_per_s": round(1000 * waited / seconds, 1),
            "load": load_figures}


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


# -- section 4: the dry-run check hammered during a run (issue 24.3), before and after
class CheckHammer:
    """``threads`` clients asking for the check of opsafe back to back, as a web page's
    <img> loop did: GET on a console of before issue 24 (no token), POST with the token on
    one after it (mostly refused 429 by its rate limit: that is the point)."""

    def __init__(self, console: ConsoleProcess, threads: int = 4) -> None:
        self.console = console
        self.threads = threads
        self.codes: dict[int, int] = {}
        self._stop = threading.Event()
        self._workers: list[threading.Thread] = []

    def _hammer(self) -> None:
        console = self.console
        method = "POST" if console.token else "GET"
        url = console.base.rstrip("/") + "/api/v1/sequences/opsafe.yaml/check"
        while not self._stop.is_set():
            request = urllib.request.Request(url, method=method, data=b"" if method == "POST"
                                             else None, headers=console.headers())
            try:
                with urllib.request.urlopen(request, timeout=120) as response:
                    response.read()
                    code = response.status
            except urllib.error.HTTPError as exc:
                code = exc.code
                if code == 429:  # refused at once: ask again as a page would, soon
                    time.sleep(0.05)
            except OSError:
                code = -1
            self.codes[code] = self.codes.get(code, 0) + 1

    def start(self) -> None:
        self._stop.clear()
        self.codes = {}
        self._workers = [threading.Thread(target=self._hammer, daemon=True)
                         for _ in range(self.threads)]
        for worker in self._workers:
            worker.start()

    def stop(self) -> dict:
        self._stop.set()
        for worker in self._workers:
            worker.join(timeout=150)
        return {"answers": dict(sorted(self.codes.items()))}


def check_ab(browser, repeats: int, baseline: Path | None) -> dict:
    """The loop's period during opsafe, quiet vs the check hammered, alternating run by
    run, in a console of this tree and (``baseline``) one of the tree before."""
    trees = [("after", ROOT)] + ([("before", baseline)] if baseline else [])
    runs: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        consoles = {name: ConsoleProcess(Path(tmp) / name, root=root) for name, root in trees}
        try:
            for console in consoles.values():  # warm-up: every measured run from Op-safe
                one_run(console, browser, 0, console.url)
            for rep in range(repeats):
                order = [(name, mode) for name, _ in trees for mode in ("quiet", "hammered")]
                for name, mode in (order if rep % 2 == 0 else order[::-1]):
                    console = consoles[name]
                    load = CheckHammer(console) if mode == "hammered" else None
                    run = one_run(console, browser, 0, console.url, load)
                    runs.setdefault(f"{name} {mode}", []).append(run)
                    s = summary(run["periods"])
                    print(f"   {name:6s} {mode:9s} rep {rep + 1}: {run['result']}, loop p50 "
                          f"{s.get('p50_ms')} p99 {s.get('p99_ms')} max {s.get('max_ms')} ms;"
                          f" console CPU {run['cpu_percent']} %"
                          + (f"; check answers {run['load']['answers']}" if run["load"] else ""),
                          flush=True)
        finally:
            for console in consoles.values():
                console.close()
    return {mode: {"loop": summary([p for run in items for p in run["periods"]]),
                   "loop_p99_per_run_ms": [summary(run["periods"]).get("p99_ms")
                                           for run in items],
                   "results": [run["result"] for run in items],
                   "check_answers": [run["load"] for run in items]}
            for mode, items in runs.items()}


# -- section 5: 50 reading + 50 non-reading live clients during a run (issue 24.4)
class LiveClients:
    """``reading`` live clients that take every message and ``idle`` ones that connect and
    never read (a small receive buffer: the console's sends to them block). They stand for
    tablets and tools elsewhere on the network, so they run in a process of their own at
    ``nice`` 10 (this script with ``--live-clients-child``), not competing with the console
    for the CPU as if they were part of it."""

    def __init__(self, console: ConsoleProcess, reading: int = 50, idle: int = 50) -> None:
        self.console = console
        self.reading = reading
        self.idle = idle
        self.proc: Any = None

    def start(self) -> None:
        self.proc = subprocess.Popen(
            ["nice", "-n", "10", sys.executable, str(Path(__file__).resolve()),
             "--live-clients-child", self.console.live_url, str(self.reading), str(self.idle)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)})
        line = self.proc.stdout.readline()
        if line.strip() != "ready":
            raise RuntimeError(f"the live clients did not connect: {line!r}")

    def stop(self) -> dict:
        self.proc.stdin.write("stop\n")
        self.proc.stdin.flush()
        figures = json.loads(self.proc.stdout.readline())
        self.proc.wait(60)
        return figures


def live_clients_child(url: str, reading: int, idle: int) -> None:
    """The live clients (see :class:`LiveClients`): prints "ready" once connected, then the
    figures as one JSON line when "stop" comes on stdin."""
    import asyncio
    import socket

    import websockets.asyncio.client

    async def main() -> None:
        done = asyncio.Event()
        received = [0] * reading
        refused = 0

        async def reader(k: int) -> None:
            nonlocal refused
            try:
                async with websockets.asyncio.client.connect(url, max_size=None) as ws:
                    while not done.is_set():
                        try:
                            await asyncio.wait_for(ws.recv(), 1.0)
                            received[k] += 1
                        except asyncio.TimeoutError:
                            continue
            except Exception:  # noqa: BLE001 - refused (the cap) or dropped: counted
                refused += 1

        host, port = re.search(r"ws://([^:/]+):(\d+)", url).groups()
        path = url.split(f":{port}", 1)[1]
        sockets = []
        for _ in range(idle):
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.connect((host, int(port)))
            sock.sendall((f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\n"
                          "Upgrade: websocket\r\nConnection: Upgrade\r\n"
                          "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                          "Sec-WebSocket-Version: 13\r\n\r\n").encode())
            sockets.append(sock)
        tasks = [asyncio.create_task(reader(k)) for k in range(reading)]
        await asyncio.sleep(2.0)  # connected (and sent the history of events)
        for k in range(reading):
            received[k] = 0
        print("ready", flush=True)
        started = time.monotonic()
        await asyncio.get_running_loop().run_in_executor(None, sys.stdin.readline)
        seconds = time.monotonic() - started
        done.set()
        await asyncio.gather(*tasks)
        for sock in sockets:
            sock.close()
        rates = [n / seconds for n in received]
        print(json.dumps({"reading": reading, "idle": idle, "refused": refused,
                          "reader_hz_median": round(float(np.median(rates)), 1),
                          "reader_hz_min": round(float(np.min(rates)), 1)}), flush=True)

    asyncio.run(main())


def clients_ab(browser, repeats: int, reading: int, idle: int,
               switch_interval: float | None = None) -> dict:
    """The loop's period during opsafe with no client and with ``reading`` + ``idle`` live
    clients, alternating run by run in one console process."""
    runs: dict[str, list[dict]] = {"none": [], "clients": []}
    with tempfile.TemporaryDirectory() as tmp:
        console = ConsoleProcess(Path(tmp), switch_interval=switch_interval)
        try:
            one_run(console, browser, 0, console.url)  # warm-up: every measured run from Op-safe
            for rep in range(repeats):
                for mode in (("none", "clients") if rep % 2 == 0 else ("clients", "none")):
                    load = LiveClients(console, reading, idle) if mode == "clients" else None
                    run = one_run(console, browser, 0, console.url, load)
                    runs[mode].append(run)
                    s = summary(run["periods"])
                    print(f"   {mode:8s} rep {rep + 1}: {run['result']}, loop p50 "
                          f"{s.get('p50_ms')} p99 {s.get('p99_ms')} max {s.get('max_ms')} ms;"
                          f" console CPU {run['cpu_percent']} %"
                          + (f"; clients {run['load']}" if run["load"] else ""), flush=True)
        finally:
            console.close()
    return {mode: {"loop": summary([p for run in items for p in run["periods"]]),
                   "loop_p99_per_run_ms": [summary(run["periods"]).get("p99_ms")
                                           for run in items],
                   "console_cpu_percent": [run["cpu_percent"] for run in items],
                   "results": [run["result"] for run in items],
                   "clients": [run["load"] for run in items]}
            for mode, items in runs.items()}


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
    if sys.argv[1:2] == ["--live-clients-child"]:
        live_clients_child(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
        return
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
                        choices=["stop", "telemetry", "idle", "check", "clients"])
    parser.add_argument("--only", action="append", default=[],
                        choices=["stop", "telemetry", "idle", "check", "clients"],
                        help="run only these sections")
    parser.add_argument("--baseline", type=Path, metavar="DIR",
                        help="section 4 also on a console of the source tree DIR (before "
                             "issue 24: git archive 2bfba80 | tar -x -C DIR)")
    parser.add_argument("--clients", default="50,50", metavar="READING,IDLE",
                        help="section 5's live clients: reading, not reading")
    parser.add_argument("--out", type=Path, default=RESULTS / "console.json")
    opts = parser.parse_args()
    if opts.only:
        opts.skip = [s for s in ("stop", "telemetry", "idle", "check", "clients")
                     if s not in opts.only]
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
                               ("halt_call_to_frame", "session.halt() -> frame"),
                               ("read_back_to_badge", "HALTED read back -> badge 'halted' "
                                "(goal < 100 ms)")):
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
        if "check" not in opts.skip:
            print(f"4. the 100 Hz loop during opsafe, quiet vs the dry-run check hammered (4 "
                  f"clients back to back), {opts.repeats} runs each, alternating"
                  + (f"; before: {opts.baseline}" if opts.baseline else "") + ":")
            results["check"] = c = check_ab(browser, opts.repeats, opts.baseline)
            for mode, row in c.items():
                s = row["loop"]
                print(f"   {mode:16s} p50 {s.get('p50_ms')} p99 {s.get('p99_ms')} max "
                      f"{s.get('max_ms')} ms; p99 per run {row['loop_p99_per_run_ms']}; "
                      f"{row['results']}")
        if "clients" not in opts.skip:
            reading, idle = (int(x) for x in opts.clients.split(","))
            print(f"5. the 100 Hz loop during opsafe, no live client vs {reading} reading + "
                  f"{idle} not reading, {opts.repeats} runs each, alternating:")
            results["clients"] = c = clients_ab(browser, opts.repeats, reading, idle,
                                                opts.switch_interval)
            for mode, row in c.items():
                s = row["loop"]
                print(f"   {mode:8s} p50 {s.get('p50_ms')} p99 {s.get('p99_ms')} max "
                      f"{s.get('max_ms')} ms; p99 per run {row['loop_p99_per_run_ms']}; "
                      f"{row['results']}")
            gap = c["clients"]["loop"].get("p99_ms", 0) - c["none"]["loop"].get("p99_ms", 0)
            print(f"   p99 with the clients - without: {gap:+.2f} ms (goal: within 2 ms)")
        if "idle" not in opts.skip:
            results["idle_cpu"] = idle = idle_cpu(browser, opts.idle_seconds)
            print(f"3. seqrun console --sim at idle: {idle['no_page']['cpu_percent']} % CPU "
                  f"with no page, {idle['one_tab']['cpu_percent']} % with one tab open")
        browser.close()
    write_json(opts.out, results)
    print(f"-> {opts.out}")


if __name__ == "__main__":
    main()
