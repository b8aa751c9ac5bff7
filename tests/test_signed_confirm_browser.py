"""A signed confirm and a breakpoint in the console's question dialog (Chromium): the
dialog asks for the name of who answers, refuses a yes without one, and the run keeps it."""

from __future__ import annotations

import json

import pytest

from consolekit import wait_for
from test_console_browser import browser, live, page  # noqa: F401  (the same page fixtures)

pytestmark = pytest.mark.slow  # a browser, a server and real-time motion

SIGNED = """\
name: Signed nudge
steps:
  - include: startup.yaml
  - confirm: {prompt: 'Is the arm clear for the nudge?', role: test conductor, sign: true}
  - move: {joints: {j1: 3}, label: Nudge j1, breakpoint: true}
"""


@pytest.fixture
def signed_file(live):
    setup, _ = live
    (setup.folder / "sequences" / "signed.yaml").write_text(SIGNED)
    return setup


def test_the_dialog_asks_who_signs_and_the_run_keeps_it(signed_file, page, tmp_path):
    setup = signed_file
    page.click("[data-sequence='signed.yaml'] button")
    page.wait_for_selector("#seq-verdict.passed", timeout=60000)
    page.click("#run")
    page.wait_for_selector("#confirm-dialog:not([hidden])", timeout=20000)
    assert page.is_visible("#confirm-name")
    assert "test conductor" in page.text_content("#confirm-name-label")
    page.click("#confirm-yes")               # no name: asked again, nothing sent
    assert page.is_visible("#confirm-name-note")
    assert page.is_visible("#confirm-dialog")
    page.fill("#confirm-name", "Katherine Johnson")
    page.screenshot(path=str(tmp_path / "signed.png"))
    page.click("#confirm-yes")
    # then the breakpoint: the same dialog, without the name field
    page.wait_for_function("document.querySelector('#confirm-text').textContent"
                           ".includes('Breakpoint before step')", timeout=20000)
    assert not page.is_visible("#confirm-name")
    page.click("#confirm-yes")
    page.wait_for_function("[...document.querySelectorAll('#events li')]"
                           ".some(li => li.textContent.includes('run_finished'))", timeout=60000)
    # the run's report is whole once the activity has ended
    report = wait_for(lambda: _finished_report(setup.runs), timeout=30)
    step = report["steps"][3]
    assert (step["signed_by"], step["signed_role"]) == ("Katherine Johnson", "test conductor")
    assert report["status"] == "passed"


def _finished_report(runs) -> dict | None:
    for folder in runs.iterdir():
        try:
            report = json.loads((folder / "report.json").read_text())
        except (OSError, ValueError):
            continue
        if "steps" in report and report.get("status"):
            return report
    return None
