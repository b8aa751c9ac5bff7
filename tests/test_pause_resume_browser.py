"""Pause and Resume from the console page (Chromium): Pause while a move runs, the page says
where the run holds once the move has ended; a Resume with the arm moved meanwhile is
refused and the page says why; back in place, Resume goes on and the run passes."""

from __future__ import annotations

import math

import pytest

from test_console_browser import browser, live, page  # noqa: F401  (the same page fixtures)

pytestmark = pytest.mark.slow  # a browser, a server and real-time motion

PAUSABLE = """\
name: Pausable
steps:
  - include: startup.yaml
  - move: {joints: {j1: 40}, label: Out}
  - move: {joints: {j1: 0}, label: Back}
  - move: {joints: {j1: 5}, label: Nudge}
"""

EVENT_SHOWN = ("(kind) => [...document.querySelectorAll('#events li')]"
               ".some(li => li.textContent.includes(' ' + kind + ' '))")


@pytest.fixture
def pausable(live):
    setup, _ = live
    (setup.folder / "sequences" / "pausable.yaml").write_text(PAUSABLE)
    return setup


def test_pause_then_resume_from_the_page(pausable, page, tmp_path):
    sim = pausable.connection.bus.arm
    page.click("[data-sequence='pausable.yaml'] button")
    page.wait_for_selector("#seq-verdict.passed", timeout=60000)
    page.click("#run")
    page.wait_for_function(EVENT_SHOWN, arg="move_planned", timeout=30000)
    page.click("#pause")
    # The move under way ends at rest first; then the page says where the run holds.
    page.wait_for_function("document.querySelector('#run-pause').textContent"
                           ".startsWith('Paused before step')", timeout=30000)
    text = page.text_content("#run-pause")
    assert "pausable.yaml:" in text, text
    assert page.text_content("#activity").startswith("paused")
    page.screenshot(path=str(tmp_path / "paused.png"))
    # The arm pushed while paused (j1 by 100°): the rest no longer holds from there.
    at = sim.positions()[1]
    sim.set_positions({1: at + math.radians(100)})
    page.click("#resume")
    page.wait_for_function("document.querySelector('#message').textContent"
                           ".includes('resume refused')", timeout=30000)
    assert "pausable.yaml:" in page.text_content("#message")
    assert page.get_attribute("#message", "class") == "error"
    assert page.text_content("#run-pause").startswith("Paused before step")
    page.screenshot(path=str(tmp_path / "refused.png"))
    sim.set_positions({1: at})
    page.click("#resume")
    page.wait_for_function(EVENT_SHOWN, arg="run_resumed", timeout=30000)
    page.wait_for_function(EVENT_SHOWN, arg="run_finished", timeout=60000)
    finished = page.evaluate("[...document.querySelectorAll('#events li')]"
                             ".filter(li => li.textContent.includes(' run_finished '))"
                             ".map(li => li.textContent)")
    assert finished and "passed" in finished[-1], finished
    assert page.text_content("#run-pause") == ""
    assert page.evaluate(f"({EVENT_SHOWN})('resume_refused')")
