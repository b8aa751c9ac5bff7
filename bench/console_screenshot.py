"""The README's screenshot of the console (docs/console.png), taken from the real page.

The console runs on the simulated arm (real time); the arm is armed and sent to Op-safe,
the Op-safe sequence is opened (validation and dry run shown) and a MOVE target is set so
that the ghost shows, then Chromium takes the picture.

Run: ``.venv/bin/python bench/console_screenshot.py [--out docs/console.png]``
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE.parent))

from consolekit import LiveServer, console_setup  # noqa: E402

CHROMIUM = os.environ.get("SEQRUN_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=HERE.parent / "docs" / "console.png")
    opts = parser.parse_args()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw, tempfile.TemporaryDirectory() as tmp:
        browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=[
            "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader", "--no-first-run"])
        setup = console_setup(Path(tmp))
        try:
            with LiveServer(setup.app()) as server:
                setup.session.arm_up()
                setup.session.home()
                setup.session.move_to_pose("totem").wait(120)
                setup.session.move_to_pose("opsafe").wait(120)
                page = browser.new_page(viewport={"width": 1500, "height": 1000})
                page.goto(server.url)
                page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                                       "&& window.seqrunConsole.statusCount > 2")
                page.click("[data-sequence='opsafe.yaml'] button")
                page.wait_for_selector("#seq-verdict", timeout=120000)
                page.fill(".move-number[data-joint=j2]", "-10")
                page.dispatch_event(".move-number[data-joint=j2]", "input")
                page.wait_for_timeout(500)
                opts.out.parent.mkdir(parents=True, exist_ok=True)
                page.screenshot(path=str(opts.out), full_page=True)
        finally:
            setup.close()
            browser.close()
    print(f"-> {opts.out}")


if __name__ == "__main__":
    main()
