"""report.html in a real browser: Chromium (the system's, driven by Playwright) renders the
page offline, every plot is there and drawn, the screenshot is not blank.

Needs Chromium at /usr/bin/chromium (Debian: ``apt-get install chromium``; CI installs it)
or at $SEQRUN_CHROMIUM. Playwright's own browser download is not used.
"""

from __future__ import annotations

import io
import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT, shipped_arm
from seqrun.cli.app import app

ARM = shipped_arm()
PLOTS = [f"plot-{n}" for n in ARM.joint_names] + ["plot-guards"]
CHROMIUM = os.environ.get("SEQRUN_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"

pytestmark = pytest.mark.slow   # a browser process


@pytest.fixture(scope="session")
def browser_type_launch_args(browser_type_launch_args):
    assert Path(CHROMIUM).is_file(), (
        f"Chromium not found at {CHROMIUM}: apt-get install chromium (or set SEQRUN_CHROMIUM)")
    return {**browser_type_launch_args, "executable_path": CHROMIUM, "headless": True,
            "args": ["--no-sandbox", "--headless", "--disable-gpu",
                     "--disable-background-networking", "--disable-component-update",
                     "--no-first-run"]}


@pytest.fixture(scope="module")
def fault_report(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("browser") / "run"
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "opsafe.yaml"),
                                      "--virtual-time", "--yes", "--plain", "--log-dir",
                                      str(folder), "--sim-fault", "4:tow_error@5"])
    assert result.exit_code == 3, result.output
    return folder / "report.html"


def distinct_colours(png: bytes) -> int:
    from PIL import Image

    image = Image.open(io.BytesIO(png)).convert("RGB")
    return len(image.getcolors(maxcolors=1 << 20) or [])


def test_report_renders_in_chromium_with_every_plot(page, fault_report):
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.set_viewport_size({"width": 1200, "height": 900})
    page.goto(fault_report.as_uri())
    assert "FAILED" in page.title()
    # Offline: the page asked for nothing but itself.
    assert requests == [fault_report.as_uri()]
    # Every plot is there, is an SVG and has a size on screen.
    assert page.locator("figure.plot").evaluate_all("els => els.map(e => e.id)") == PLOTS
    assert page.locator("svg").count() == len(PLOTS)
    for plot in PLOTS:
        box = page.locator(f"#{plot} svg").bounding_box()
        assert box and box["width"] > 500 and box["height"] > 150, plot
        # Drawn, not empty: lines, text and the red fault marker in many colours.
        assert distinct_colours(page.locator(f"#{plot}").screenshot()) > 20, plot
    # The fault box is visible at the top of the page.
    assert page.locator("#fault").is_visible()
    shot = page.screenshot(full_page=True)
    assert distinct_colours(shot) > 50
