"""Run from here on the console page (Chromium): each step after the first has a "run from
here" button that asks first; with the arm not where the step expects it the page says
why (the full line, below the buttons) and nothing moves; declining the question sends
nothing; with the arm in place only the steps from there run."""

from __future__ import annotations

import pytest

from test_console_browser import browser, live, page  # noqa: F401  (the page fixtures)

pytestmark = pytest.mark.slow  # a browser, a server and real-time motion

FROM_HERE = """\
name: From here
steps:
  - move: {joints: {j1: 6}, label: Out}
  - move: {joints: {j1: 2}, label: Half back}
  - move: {joints: {j1: 0}, label: Back}
"""

EVENT_SHOWN = ("(kind) => [...document.querySelectorAll('#events li')]"
               ".some(li => li.textContent.includes(' ' + kind + ' '))")


@pytest.fixture
def from_here(live):
    setup, _ = live
    (setup.folder / "sequences" / "from_here.yaml").write_text(FROM_HERE)
    for done in (setup.session.arm_up(), setup.session.home()):
        assert done.ok, done
    return setup


def test_run_from_a_step_on_the_page(from_here, page, tmp_path):
    setup = from_here
    page.click("[data-sequence='from_here.yaml'] button")
    page.wait_for_selector("#seq-verdict.passed", timeout=60000)
    assert page.locator("#seq-steps li[data-step='1'] button.from-here").count() == 0
    button = "#seq-steps li[data-step='2'] button.from-here"
    assert page.is_enabled(button)
    motions = setup.wire.motions()

    # Declined: nothing is sent.
    asked: list[str] = []

    def decline(dialog) -> None:
        asked.append(dialog.message)
        dialog.dismiss()

    page.once("dialog", decline)
    page.click(button)
    page.wait_for_timeout(300)
    assert asked == ["Run from step 2 (Half back)? Step 1 is not run."]
    assert setup.wire.motions() == motions

    # The arm at Park (j1 0°), step 2 expects it at 6°: refused, the reason on the page.
    page.once("dialog", lambda dialog: dialog.accept())
    page.click(button)
    page.wait_for_function("document.querySelector('#run-refused').textContent.length > 0",
                           timeout=20000)
    text = page.text_content("#run-refused")
    assert text.startswith("Run from_here.yaml from step 2 refused: "), text
    assert "from_here.yaml:4:" in text and "not where this step expects it" in text, text
    assert "expected 6.00°" in text, text
    assert page.get_attribute("#message", "class") == "error"
    page.screenshot(path=str(tmp_path / "run-from-refused.png"))
    assert setup.wire.motions() == motions

    # The arm where step 2 expects it: steps 2 and 3 run, the page clears the refusal.
    setup.session.move_to_joints({"j1": 6.0})
    page.wait_for_function("(s => s.activity === 'idle' && Math.abs(s.joints[0].position_deg"
                           " - 6) < 0.3)(window.seqrunConsole.status)", timeout=20000)
    page.once("dialog", lambda dialog: dialog.accept())
    page.click(button)
    page.wait_for_function(EVENT_SHOWN, arg="run_finished", timeout=60000)
    assert page.text_content("#run-refused") == ""
    finished = page.evaluate("[...document.querySelectorAll('#events li')]"
                             ".filter(li => li.textContent.includes(' run_finished '))"
                             ".map(li => li.textContent)")
    assert finished and "passed" in finished[-1], finished
    page.wait_for_selector("#seq-steps li[data-step='3'].current", timeout=10000)
    assert page.get_attribute("#seq-steps li[data-step='1']", "class") == "not-run"
    assert page.get_attribute("#seq-steps li[data-step='2']", "class") == "done"
    # the telemetry after the run's end (the page's status lags the run's events)
    page.wait_for_function("Math.abs(window.seqrunConsole.status.joints[0].position_deg)"
                           " < 0.3", timeout=10000)
    page.screenshot(path=str(tmp_path / "run-from-passed.png"))
