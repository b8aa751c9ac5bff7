"""The gripper panel in a real browser (Chromium via Playwright, as
tests/test_console_browser.py): the state it shows is the module's own. A module powers on
not homed with its brake on (thesis 5.1, the simulator models it): the page says "not homed",
never FAULT; after Arm and Home it is ready; a Halt (STOP) is a fault and says so."""

from __future__ import annotations

import pytest
from consolekit import LiveServer, console_setup
from test_console_browser import arm_up, browser, shows  # noqa: F401 (the fixture)

pytestmark = pytest.mark.slow  # a browser, a server and the simulated arm in real time


@pytest.fixture
def served(tmp_path):
    setup = console_setup(tmp_path)
    setup.connection.bus.inner.arm.add_gripper(8)  # the arm file's PG 70, at module 8
    with LiveServer(setup.app()) as server:
        yield setup, server
    setup.close()


def gripper_line(page) -> str:
    return page.text_content("#gripper-state") or ""


def test_the_gripper_shows_its_true_state_not_a_fault_at_power_on(browser, served,  # noqa: F811
                                                                  tmp_path):
    setup, server = served
    context = browser.new_context(viewport={"width": 1500, "height": 1000})
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.goto(server.url)
        page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready",
                               timeout=20000)
        page.wait_for_selector("#gripper-panel:not([hidden])", timeout=10000)
        shows(page, "#gripper-state", "mm open")
        # named as the arm file's gripper section names it
        assert "PG 70, module 8, stroke 70 mm" in page.text_content("#gripper-name")
        idle = gripper_line(page)
        page.screenshot(path=str(tmp_path / "gripper-power-on.png"), full_page=True)
        assert "70.0 mm open, not holding, not homed" in idle, idle
        assert "FAULT" not in idle and "BRAKEACTIVE" in idle
        assert "fault" not in (page.get_attribute("#gripper-state", "class") or "")

        arm_up(page)  # Arm, then Home: the broadcast Home homes the gripper too
        page.wait_for_function("document.querySelector('#gripper-state').textContent"
                               ".endsWith(', ready')", timeout=10000)

        page.dispatch_event("#stop", "pointerdown", {"button": 0})
        shows(page, "#gripper-state", "FAULT")
        halted = gripper_line(page)
        assert "HALTED" in halted, halted
        assert "fault" in (page.get_attribute("#gripper-state", "class") or "")
        page.screenshot(path=str(tmp_path / "gripper-halted.png"), full_page=True)
        assert not errors, errors
    finally:
        context.close()
