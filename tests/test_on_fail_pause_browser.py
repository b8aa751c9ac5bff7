"""A step's ``on_fail: pause`` in the console's question dialog (Chromium): Retry, Skip and
Abort buttons instead of Yes and No; Skip goes on and the run keeps the choice."""

from __future__ import annotations

import json

import pytest

from consolekit import wait_for
from test_console_browser import browser, live, page  # noqa: F401  (the same page fixtures)

pytestmark = pytest.mark.slow  # a browser, a server and a run

PAUSE = """\
name: Pause in the console
steps:
  - check: {that: 'tool.z_mm > 5000', on_fail: pause, label: Never}
  - wait: {seconds: 0.1, label: After}
"""


def test_the_dialog_offers_retry_skip_abort_and_skip_goes_on(live, page, tmp_path):
    setup, _ = live
    (setup.folder / "sequences" / "pause.yaml").write_text(PAUSE)
    page.reload()
    page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready", timeout=20000)
    page.click("[data-sequence='pause.yaml'] button")
    page.wait_for_selector("#seq-verdict", timeout=60000)
    page.click("#run")
    page.wait_for_selector("#confirm-dialog:not([hidden])", timeout=20000)
    assert "Retry, skip or abort?" in page.text_content("#confirm-text")
    assert not page.is_visible("#confirm-yes") and not page.is_visible("#confirm-no")
    buttons = page.locator("#confirm-choices button")
    assert buttons.all_text_contents() == ["Retry", "Skip", "Abort"]
    page.screenshot(path=str(tmp_path / "on_fail_pause.png"))  # (looked at by hand)
    page.click("#confirm-choices button[data-choice='skip']")
    assert page.is_hidden("#confirm-dialog")
    page.wait_for_function("[...document.querySelectorAll('#events li')]"
                           ".some(li => li.textContent.includes('run_finished'))", timeout=60000)
    report = wait_for(lambda: _finished_report(setup.runs), timeout=30)
    assert report["status"] == "passed"
    never = report["steps"][0]
    assert never["status"] == "failed" and never["skipped_by"] == "operator"
    assert never["operator_choices"][0]["by"] == "console"


def _finished_report(runs) -> dict | None:
    for folder in runs.iterdir():
        try:
            report = json.loads((folder / "report.json").read_text())
        except (OSError, ValueError):
            continue
        if "steps" in report and report.get("status"):
            return report
    return None
