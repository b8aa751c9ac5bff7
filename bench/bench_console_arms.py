"""The console of two arms: each arm's 100 Hz loop while both run, beside one arm alone.

A ``seqrun console --sim`` process (as a facility runs it) in a campaign with arms A and B
(each its own simulated bus and session) runs ``sequences/opsafe.yaml`` through each arm's
API (``POST /api/v1/arms/{id}/run``), the modes alternating run by run (the order turns
round every repetition):

- ``one``: arm A alone (B idle: its status poll only);
- ``both``: A and B at the same time;
- ``both-tabs``: both, with ``--tabs`` (3) tabs of the two-arm page open in Chromium
  (software WebGL on the same cores).

Per mode and arm: the loop's period (spacing of the run's ``setpoint`` events) p50/p99/max
pooled over the runs. Goal (issue 28.5 for the console): each arm's p99 with both running
within 2 ms of one arm alone. Say the host's load beside a figure; ``--rt-priority N`` runs
the console with it (needs root or CAP_SYS_NICE).

Run: ``.venv/bin/python bench/bench_console_arms.py [--repeats 3] [--modes one,both,both-tabs]
[--tabs 3] [--rt-priority N] [--out FILE]``
"""

from __future__ import annotations

import argparse
import json
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


HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from loop_pairs import periods as setpoint_periods  # noqa: E402
from loop_pairs import summary  # noqa: E402
from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402


def event_periods(folder: Path) -> list[float]:
    """The loop's periods of one arm's run (its events.jsonl)."""
    lines = (folder / "events.jsonl").read_text().splitlines()
    return setpoint_periods([json.loads(line) for line in lines])

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader", "--disable-background-timer-throttling",
        "--disable-renderer-backgrounding", "--disable-backgrounding-occluded-windows"]
CAMPAIGN = """\
[campaign]
name = "Two-arm console bench"

[arms.A]
arm = "lwa3"

[arms.B]
arm = "lwa3"
base = { position_mm = [0, 900, 0], rpy_deg = [0, 0, 180] }
"""


class Console:
    """``seqrun console --sim --port 0`` in the two-arm campaign ``folder``."""

    def __init__(self, folder: Path, rt_priority: int | None) -> None:
        args = [sys.executable, "-m", "seqrun", "console", "--sim", "--port", "0"]
        if rt_priority is not None:
            args += ["--rt-priority", str(rt_priority)]
        self.proc = subprocess.Popen(args, cwd=folder, env={"PYTHONPATH": str(ROOT),
                                                            "PATH": "/usr/bin:/bin"},
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True)
        self.url = ""
        while not self.url:
            line = self.proc.stdout.readline()
            if not line:
                raise RuntimeError("seqrun console ended before printing its URL")
            found = re.search(r"(http://\S+)", line)
            self.url = found.group(1) if found else ""
        threading.Thread(target=lambda: [None for _ in self.proc.stdout], daemon=True).start()
        self.base = self.url.split("?", 1)[0].rstrip("/")
        self.token = self.url.split("token=", 1)[1]
        self.client = None
        self.client = self.call("POST", "/control/take", {"name": "bench"})["token"]

    def call(self, method: str, path: str, body: dict | None = None) -> Any:
        headers = {"Content-Type": "application/json", "Authorization": f"Bearer {self.token}"}
        if self.client:
            headers["X-Seqrun-Control"] = self.client
        request = urllib.request.Request(self.base + "/api/v1" + path, method=method,
                                         data=None if body is None else json.dumps(body).encode(),
                                         headers=headers)
        with urllib.request.urlopen(request, timeout=60) as response:
            return json.loads(response.read())

    def close(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def one_run(console: Console, browser, arms: list[str], tabs: int) -> dict[str, list[float]]:
    for arm in ("A", "B"):
        if console.call("GET", f"/arms/{arm}/status")["activity"] in ("halted", "faulted"):
            console.call("POST", f"/arms/{arm}/reset")
    pages = []
    for _ in range(tabs):
        page = browser.new_context(viewport={"width": 1400, "height": 950}).new_page()
        page.goto(console.url)
        page.wait_for_function("window.seqrunArms && window.seqrunArms.ready", timeout=30000)
        pages.append(page)
    for arm in arms:
        console.call("POST", f"/arms/{arm}/run", {"sequence": "opsafe.yaml"})
    folders: dict[str, str] = {}
    answered: set[tuple[str, str]] = set()
    started = time.monotonic()
    while time.monotonic() - started < 300:
        time.sleep(0.25)
        running = False
        for arm in arms:
            status = console.call("GET", f"/arms/{arm}/status")
            running |= status["activity"] in ("running", "paused")
            for event in console.call("GET", f"/arms/{arm}/events"):
                if event["type"] == "activity_started" and event.get("kind") == "run" \
                        and event.get("detail", {}).get("run_dir"):
                    folders[arm] = event["detail"]["run_dir"]  # (the newest: this run's)
                question = event.get("question_id")  # (ids are per arm's session)
                if event["type"] == "confirm_requested" and (arm, question) not in answered:
                    answered.add((arm, question))
                    try:
                        console.call("POST", f"/arms/{arm}/answer",
                                     {"question_id": question, "yes": True})
                    except urllib.error.HTTPError:
                        pass
        if not running:
            break
    for page in pages:
        page.context.close()
    for arm in arms:
        if arm not in folders:
            print(f"   (arm {arm}: no run folder; its events: "
                  f"{console.call('GET', f'/arms/{arm}/events')[-3:]})")
    return {arm: event_periods(Path(folders[arm])) if arm in folders else [] for arm in arms}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--modes", default="one,both,both-tabs")
    parser.add_argument("--tabs", type=int, default=3)
    parser.add_argument("--rt-priority", type=int, metavar="N")
    parser.add_argument("--out", type=Path, default=RESULTS / "console_arms.json")
    options = parser.parse_args()
    modes = options.modes.split(",")
    folder = Path(tempfile.mkdtemp(prefix="bench-console-arms-"))
    for kind in ("arms", "poses", "sequences"):
        shutil.copytree(ROOT / kind, folder / kind)
    (folder / "seqrun.toml").write_text(CAMPAIGN)
    pooled: dict[str, dict[str, list[float]]] = {m: {"A": [], "B": []} for m in modes}
    console = Console(folder, options.rt_priority)
    browser = None
    try:
        if any(m.endswith("tabs") for m in modes):
            from playwright.sync_api import sync_playwright

            pw = sync_playwright().start()
            browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
        for k in range(options.repeats):
            for mode in modes[k % len(modes):] + modes[:k % len(modes)]:
                arms = ["A"] if mode == "one" else ["A", "B"]
                periods = one_run(console, browser, arms,
                                  options.tabs if mode.endswith("tabs") else 0)
                for arm, values in periods.items():
                    pooled[mode][arm] += values
                print(f"  run {k + 1} {mode}: " + ", ".join(
                    f"{a} p99 {summary([{'periods': v, 'exit_code': None}])['p99_ms']} ms"
                    if v else f"{a}: no periods" for a, v in periods.items()), flush=True)
    finally:
        console.close()
        if browser is not None:
            browser.close()
    result = {"machine": machine(), "repeats": options.repeats, "tabs": options.tabs,
              "rt_priority": options.rt_priority,
              "loop": {m: {a: summary([{"periods": v, "exit_code": None}])
                           for a, v in arms.items() if v}
                       for m, arms in pooled.items()}}
    for mode, arms in result["loop"].items():
        for arm, figures in arms.items():
            print(f"{mode:10s} arm {arm}: {figures}")
    write_json(options.out, result)
    shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
