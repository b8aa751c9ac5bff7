"""The operator console: STOP latency, telemetry rate with three tabs, idle CPU.

1. **STOP click -> Halt frame on the wire**, over ``--clicks`` (100) presses of the page's
   STOP button in Chromium (the arm is reset between presses). The press time is the
   browser's event time (``performance.timeOrigin + event.timeStamp`` of the pointerdown);
   the Halt time is when the session handed the Halt broadcast to the bus (wall clock, same
   machine). Goal: p99 < 20 ms.
2. **Telemetry updates per second in the browser** with three tabs open during a run of
   ``sequences/opsafe.yaml`` (status messages each tab received per second while the arm
   moved), and the **100 Hz loop's period** (spacing of the run's ``setpoint`` events)
   with the three tabs vs with no page open. Goals: >= 50 Hz in every tab; the loop's p99
   period unchanged.
3. **Idle CPU** of a ``seqrun console --sim`` process (user + system time over
   ``--idle-seconds``), with no page and with one tab open.

Chromium: /usr/bin/chromium or $SEQRUN_CHROMIUM (Playwright drives it; no browser download).

Run: ``.venv/bin/python bench/bench_console.py [--clicks 100] [--idle-seconds 10]``
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
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from bench_liveview import event_periods, summary  # noqa: E402
from consolekit import LiveServer, console_setup, wait_for  # noqa: E402
from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

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


def run_opsafe(setup) -> tuple[list[float], str]:
    """The 100 Hz loop's periods of one run of opsafe, and how the run ended."""
    setup.session.reset()
    activity = setup.session.run_sequence(setup.folder / "sequences" / "opsafe.yaml",
                                          assume_yes=True)
    result = activity.wait(300)
    folder = Path(result.run_dir) if result.run_dir else None
    return (event_periods(folder) if folder else []), f"{result.status}: {result.message}"


def telemetry(browser, setup, server) -> dict:
    baseline, ended = run_opsafe(setup)  # (the second run starts at Op-safe: via Totem again)
    print(f"   run without pages: {ended}")
    pages = [open_page(browser, server.url) for _ in range(3)]
    rates: list[list[float]] = [[] for _ in pages]
    moving = threading.Event()
    done = threading.Event()

    def run() -> None:
        nonlocal with_tabs
        moving.set()
        with_tabs, ended = run_opsafe(setup)
        print(f"   run with three tabs: {ended}")
        done.set()

    with_tabs: list[float] = []
    worker = threading.Thread(target=run)
    worker.start()
    counts = [p.evaluate("window.seqrunConsole.statusCount") for p in pages]
    last = time.perf_counter()
    while not done.wait(1.0):
        now = time.perf_counter()
        activity = setup.session.status().activity
        new = [p.evaluate("window.seqrunConsole.statusCount") for p in pages]
        if activity == "running":
            for k in range(len(pages)):
                rates[k].append((new[k] - counts[k]) / (now - last))
        counts, last = new, now
    worker.join()
    for p in pages:
        p.context.close()
    return {"tabs": [{"median_hz": round(float(np.median(r)), 1) if r else None,
                      "min_hz": round(float(np.min(r)), 1) if r else None, "seconds": len(r)}
                     for r in rates],
            "loop_without_pages": summary(baseline), "loop_with_three_tabs": summary(with_tabs)}


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--clicks", type=int, default=100)
    parser.add_argument("--idle-seconds", type=float, default=10.0)
    parser.add_argument("--skip", action="append", default=[],
                        choices=["stop", "telemetry", "idle"])
    parser.add_argument("--out", type=Path, default=RESULTS / "console.json")
    opts = parser.parse_args()
    from playwright.sync_api import sync_playwright

    results: dict = {"machine": machine()}
    with sync_playwright() as pw, tempfile.TemporaryDirectory() as tmp:
        browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
        TimedSession.halt_calls = []
        setup = console_setup(Path(tmp), session_class=TimedSession)
        try:
            with LiveServer(setup.app()) as server:
                if "stop" not in opts.skip:
                    results["stop_to_halt_frame"] = stop_latency(browser, setup, server,
                                                                 opts.clicks)
                    r = results["stop_to_halt_frame"]
                    print(f"1. STOP press -> Halt frame on the wire, {r['n']} presses: p50 "
                          f"{r['p50_ms']} ms, p99 {r['p99_ms']} ms, max {r['max_ms']} ms "
                          f"(goal p99 < 20 ms)")
                    for key, label in (("press_to_halt_call", "press -> session.halt()"),
                                       ("halt_call_to_frame", "session.halt() -> frame")):
                        part = r[key]
                        print(f"   {label}: p50 {part['p50_ms']} ms, p99 {part['p99_ms']} ms, "
                              f"max {part['max_ms']} ms")
                if "telemetry" not in opts.skip:
                    results["telemetry"] = t = telemetry(browser, setup, server)
                    print("2. telemetry in the browser, three tabs, during opsafe: "
                          + ", ".join(f"tab {k + 1}: median {tab['median_hz']} Hz "
                                      f"(min {tab['min_hz']})"
                                      for k, tab in enumerate(t["tabs"])) + " (goal >= 50 Hz)")
                    for key in ("loop_without_pages", "loop_with_three_tabs"):
                        s = t[key]
                        print(f"   100 Hz loop {key.replace('_', ' ')}: {s.get('cycles')} "
                              f"cycles, p50 {s.get('p50_ms')} ms, p99 {s.get('p99_ms')} ms, "
                              f"max {s.get('max_ms')} ms")
        finally:
            setup.close()
        if "idle" not in opts.skip:
            results["idle_cpu"] = idle = idle_cpu(browser, opts.idle_seconds)
            print(f"3. seqrun console --sim at idle: {idle['no_page']['cpu_percent']} % CPU "
                  f"with no page, {idle['one_tab']['cpu_percent']} % with one tab open")
        browser.close()
    write_json(opts.out, results)
    print(f"-> {opts.out}")


if __name__ == "__main__":
    main()
