"""The console in a real browser: Chromium (Debian's, driven by Playwright) on the page served
by uvicorn, on a real arm session over the simulated arm, in real time.

Needs Chromium at /usr/bin/chromium (``apt-get install chromium``; CI installs it) or at
$SEQRUN_CHROMIUM; Playwright's own browser download is not used. Screenshots of every test
are left in its tmp folder (``pytest --basetemp DIR`` keeps them where you want).
"""

from __future__ import annotations

import io
import os
import shutil
import time
from pathlib import Path

import pytest
from consolekit import LiveServer, console_setup, wait_for

CHROMIUM = os.environ.get("SEQRUN_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"

pytestmark = pytest.mark.slow  # a browser, a server and real-time motion


@pytest.fixture(scope="module")
def browser(playwright):
    assert Path(CHROMIUM).is_file(), (
        f"Chromium not found at {CHROMIUM}: apt-get install chromium (or set SEQRUN_CHROMIUM)")
    # WebGL through SwiftShader (software): the 3D view draws without a GPU.
    browser = playwright.chromium.launch(
        executable_path=CHROMIUM, headless=True,
        args=["--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
              "--enable-unsafe-swiftshader", "--disable-background-networking",
              "--disable-component-update", "--no-first-run"])
    yield browser
    browser.close()


@pytest.fixture
def live(tmp_path):
    setup = console_setup(tmp_path)
    with LiveServer(setup.app()) as server:
        yield setup, server
    setup.close()


@pytest.fixture
def page(browser, live, tmp_path):
    setup, server = live
    context = browser.new_context(viewport={"width": 1500, "height": 1000})
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.requests = requests  # type: ignore[attr-defined]
    page.goto(server.url)
    page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                           "&& window.seqrunConsole.statusCount > 1", timeout=20000)
    yield page
    try:
        page.screenshot(path=str(tmp_path / "console.png"), full_page=True)
    except Exception:  # noqa: BLE001 - a test that closed its page
        pass
    assert not errors, errors
    context.close()


def status_of(page) -> dict:
    return page.evaluate("window.seqrunConsole.status")


def joint(page, name: str) -> float:
    return next(j["position_deg"] for j in status_of(page)["joints"] if j["name"] == name)


FINISHED_SHOWN = ("[...document.querySelectorAll('#events li')]"
                  ".filter((li) => li.textContent.includes(' activity_finished ')).length")


def arm_up(page) -> None:
    """ARM UP and HOME, each to its end as the page knows it: the reply and then the
    activity_finished event, which may come later over the WebSocket on a busy host (the
    MOVE sliders follow the arm again at that event, so a target typed before it is lost)."""
    for button in ("#cmd-arm", "#cmd-home"):
        finished = page.evaluate(FINISHED_SHOWN)
        page.click(button)
        page.wait_for_function("document.querySelector('#message').textContent.includes(': ')",
                               timeout=20000)
        assert "error" not in (page.get_attribute("#message", "class") or ""), (
            button, page.text_content("#message"))
        page.wait_for_function(f"{FINISHED_SHOWN} > {finished}", timeout=20000)
        page.evaluate("document.querySelector('#message').textContent = ''")


def shows(page, selector: str, text: str) -> None:
    """The page shows ``text`` in ``selector`` (the numbers are painted a few times a
    second, not at every status)."""
    page.wait_for_function("([sel, text]) => document.querySelector(sel).textContent"
                           ".includes(text)", arg=[selector, text], timeout=5000)


def distinct_colours(png: bytes) -> int:
    from PIL import Image

    image = Image.open(io.BytesIO(png)).convert("RGB")
    return len(image.getcolors(maxcolors=1 << 20) or [])


def test_page_loads_with_live_telemetry_and_the_3d_view(page, live):
    setup, _ = live
    # The title is written when the page paints, a few times a second, not at every status.
    page.wait_for_function("document.title.includes('SIMULATOR')", timeout=5000)
    assert "SIMULATOR" in page.title()
    first = page.evaluate("window.seqrunConsole.statusCount")
    wait_for(lambda: page.evaluate("window.seqrunConsole.statusCount") > first + 3)
    assert page.text_content("#tlm-j2 .pos") == "-90.00"  # Park
    assert page.text_content("#conn") == "live"
    # Offline: the page asks for nothing but the console itself (three.js included).
    assert all(url.startswith(live[1].url) for url in page.requests), page.requests
    assert any(url.endswith("three.module.min.js") for url in page.requests)
    # The 3D view is drawn (WebGL), not blank.
    assert distinct_colours(page.locator("#view3d canvas").screenshot()) > 40
    # Its kinematics are the validator's: the page's frames at a pose equal seqrun's.
    import numpy as np

    from seqrun.arm.kinematics import Chain, frame_transforms

    q = [20, -30, 0, 45, -10, 60, 15]
    ours = np.array(page.evaluate(f"window.seqrunConsole.frames(window.seqrunConsole.arm.chain, {q})"))
    assert np.allclose(ours, frame_transforms(Chain.from_arm(setup.arm), np.radians(q)),
                       atol=1e-6)
    # Hovering a pose shows its ghost before anything is sent.
    page.hover("[data-pose=opsafe]")
    assert page.evaluate("window.seqrunConsole.view.ghost.group.visible") is True
    assert setup.wire.motions() == 0


def test_stop_click_esc_and_space_send_the_halt(page, live):
    setup, _ = live
    arm_up(page)
    for press in (lambda: page.click("#stop"), lambda: page.keyboard.press("Escape"),
                  lambda: page.keyboard.press("Space"), lambda: page.click("#stop")):
        before = time.perf_counter()
        press()
        wait_for(lambda: setup.wire.halts(before), timeout=5)
    page.wait_for_function("window.seqrunConsole.status.activity === 'halted'")
    shows(page, "#activity", "halted")
    # The modules' HALTED shows in red and stays latched after the Reset until acknowledged.
    page.wait_for_function("window.seqrunConsole.status.joints.every(j => j.fault)")
    shows(page, "#tlm-j1 .flags", "HALTED")
    assert "fault" in page.get_attribute("#tlm-j1", "class")
    page.click("#cmd-reset")
    page.wait_for_function("window.seqrunConsole.status.joints.every(j => !j.fault)",
                           timeout=10000)
    shows(page, "#tlm-j1 .flags", "was")
    assert "latched" in page.get_attribute("#tlm-j1", "class")
    # the longest state text (flags and the latched ones) wraps inside the telemetry panel
    # on a lab PC's screen
    page.set_viewport_size({"width": 1400, "height": 950})
    page.wait_for_timeout(300)  # (the page paints its numbers a few times a second)
    right = page.evaluate("[document.querySelector('#telemetry').getBoundingClientRect().right,"
                          " document.querySelector('#telemetry').parentElement"
                          ".getBoundingClientRect().right]")
    assert right[0] <= right[1], right
    page.click("#ack-faults")
    assert page.get_attribute("#tlm-j1", "class") in ("", None)


def test_jog_hold_moves_and_release_stops(page, live):
    setup, _ = live
    # The page's hold and release, not the deadman's timing (tests/test_session.py holds
    # that at virtual time): a loaded CI machine can delay a renewal past 200 ms.
    setup.session.jog_deadman_s = 1.0
    arm_up(page)
    start = joint(page, "j1")
    box = page.locator(".jog-plus[data-joint=j1]").bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    moving = wait_for(lambda: (q := joint(page, "j1")) > start + 0.5 and q, timeout=5)
    page.wait_for_timeout(600)
    assert joint(page, "j1") > moving + 0.5  # still going while held
    page.mouse.up()
    page.wait_for_function("window.seqrunConsole.status.activity === 'idle'", timeout=5000)
    stopped = joint(page, "j1")
    page.wait_for_timeout(500)
    assert joint(page, "j1") == pytest.approx(stopped, abs=0.1)
    assert stopped > start + 1.0
    assert not setup.wire.halts()


def test_a_sequence_with_a_confirm_runs_from_the_page(page, live, tmp_path):
    setup, _ = live
    page.click("[data-sequence='confirm_nudge.yaml'] button")
    page.wait_for_selector("#seq-verdict.passed", timeout=60000)
    assert "dry run passed" in page.text_content("#seq-dryrun")
    page.click("#run")
    page.wait_for_selector("#confirm-dialog:not([hidden])", timeout=20000)
    assert "clear for the nudge" in page.text_content("#confirm-text")
    page.screenshot(path=str(tmp_path / "confirm.png"))
    # STOP stays visible and clickable above the dialog.
    box = page.locator("#stop").bounding_box()
    on_top = page.evaluate(f"document.elementFromPoint({box['x'] + 20}, {box['y'] + 20}).id")
    assert on_top == "stop"
    page.click("#confirm-yes")
    page.wait_for_function("[...document.querySelectorAll('#events li')]"
                           ".some(li => li.textContent.includes('run_finished'))", timeout=30000)
    assert page.get_attribute("#seq-steps li[data-step='5']", "class") == "current"
    assert joint(page, "j1") == pytest.approx(3, abs=0.3)
    page.wait_for_selector("#runs li a", timeout=10000)
    assert "Confirm then nudge" in page.text_content("#runs li a")


def test_a_refused_move_shows_why(page, live):
    setup, _ = live
    arm_up(page)
    page.click("#stop")
    page.wait_for_function("window.seqrunConsole.status.activity === 'halted'")
    before = time.perf_counter()
    page.fill(".move-number[data-joint=j1]", "10")
    page.click("#cmd-move")
    page.wait_for_selector("#message.error", timeout=5000)
    message = page.text_content("#message")
    assert message and "\n" not in message and "Traceback" not in message
    assert setup.wire.motions(before) == 0


def test_closing_the_tab_mid_move_is_a_controlled_stop(page, live):
    setup, _ = live
    arm_up(page)
    page.fill(".move-number[data-joint=j1]", "60")
    page.click("#cmd-move")
    wait_for(lambda: setup.session.status().joints[0].position_deg > 2, timeout=10)
    page.close()
    wait_for(lambda: setup.session.status().activity == "idle", timeout=10)
    assert 2 < setup.session.status().joints[0].position_deg < 50
    assert not setup.wire.halts()  # a controlled stop, not a Halt


# Frames the 3D view draws (three.js clears once per frame) and redraws of the telemetry
# table (one mutation batch per redraw), counted in the browser without the page's help.
COUNT_DRAWING = """
window.__frames = 0;
for (const C of [WebGLRenderingContext, WebGL2RenderingContext]) {
  const clear = C.prototype.clear;
  C.prototype.clear = function (...args) { window.__frames += 1; return clear.apply(this, args); };
}
window.__redraws = 0;
document.addEventListener("DOMContentLoaded", () => {
  new MutationObserver(() => { window.__redraws += 1; }).observe(
    document.querySelector("#telemetry tbody"),
    { subtree: true, childList: true, characterData: true });
});
"""


def drawing(page) -> tuple[int, int, int]:
    return page.evaluate("[window.seqrunConsole.statusCount, window.__frames, window.__redraws]")


def test_the_page_receives_every_status_but_draws_only_changes_at_a_human_rate(page, live):
    # The page shares the PC (and maybe software WebGL) with the 100 Hz loop: it counts
    # every status, paints only what changed, the 3D view and the numbers in the same frames
    # and the numbers at most 10 times a second.
    setup, _ = live
    page.add_init_script(COUNT_DRAWING)
    page.reload()
    page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                           "&& window.seqrunConsole.statusCount > 1 && window.__frames > 0",
                           timeout=20000)
    page.wait_for_timeout(1000)
    still = drawing(page)
    page.wait_for_timeout(2000)
    after = drawing(page)
    assert after[0] > still[0]  # statuses (the idle poll, heartbeats) keep arriving ...
    assert after[1] == still[1]  # ... the arm did not move: not one frame drawn
    arm_up(page)
    page.click("[data-pose=totem]")  # from Park: ~8 s of motion
    page.wait_for_function("window.seqrunConsole.status.activity === 'moving'", timeout=10000)
    page.wait_for_timeout(500)
    t0, before = time.monotonic(), drawing(page)
    page.wait_for_timeout(3000)
    t1, moving = time.monotonic(), drawing(page)
    assert setup.session.status().activity == "moving"  # still under way: a fair window
    seconds = t1 - t0
    statuses, frames, redraws = (b - a for a, b in zip(before, moving))
    assert frames > 0 and redraws > 0  # the moving arm is drawn ...
    assert frames <= 20 * seconds + 1, (frames, seconds)  # ... at most 20 frames a second
    assert redraws <= 10 * seconds + 2, (redraws, seconds)  # ... numbers at most 10 a second
    assert statuses > redraws  # every status received, far fewer drawn
    # The numbers do not wait for the 3D view: with WebGL in software its frames come at
    # 4 a second at most, the numbers at up to 10 (issue 24.7: 1.3-4.3 a second).
    assert page.evaluate("window.seqrunConsole.view.software") is True
    assert redraws >= 6 * seconds, (redraws, frames, seconds)


# --------------------------------------------------------------------- issue 24
LONG_MOVE = """\
name: Long move
description: start-up, then j1 turns by 60 degrees (several seconds)
steps:
  - include: startup.yaml
  - move: {joints: {j1: 60}, label: Turn j1}
"""


def test_the_page_says_it_lost_the_console_and_stop_says_it_failed(browser, tmp_path):
    """Item 5: the console killed mid-move. The page kept showing MOVING and MOVE: ok."""
    import signal

    from consolekit import console_process

    proc, url = console_process(tmp_path / "runs")
    context = browser.new_context(viewport={"width": 1500, "height": 1000})
    try:
        page = context.new_page()
        page.goto(url)
        page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                               "&& window.seqrunConsole.statusCount > 1", timeout=30000)
        arm_up(page)
        page.fill(".move-number[data-joint=j1]", "90")
        page.click("#cmd-move")
        page.wait_for_function("window.seqrunConsole.status.activity === 'moving'",
                               timeout=10000)
        shows(page, "#activity", "moving")
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        page.wait_for_selector("#lost-banner:not([hidden])", timeout=5000)
        banner = page.text_content("#lost-banner")
        assert "unreachable" in banner and "unknown" in banner and "emergency stop" in banner
        assert "lost" in page.get_attribute("body", "class")
        assert page.text_content("#activity") == "unknown"  # not "moving"
        assert "MOVE: ok" not in page.text_content("#message")
        grey = page.evaluate("getComputedStyle(document.querySelector('#grid')).filter")
        assert "grayscale" in grey
        page.screenshot(path=str(tmp_path / "lost.png"))
        page.click("#stop")
        page.wait_for_function("document.querySelector('#message').textContent"
                               ".startsWith('STOP FAILED')", timeout=10000)
        message = page.text_content("#message")
        assert "unreachable" in message and "unknown" in message and "emergency stop" in message
        page.screenshot(path=str(tmp_path / "stop_failed.png"))
    finally:
        context.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_frozen_console_is_lost_contact_too_and_comes_back(browser, tmp_path):
    """No TCP close (the process stopped, a cable pulled): two silent seconds are enough."""
    import signal

    from consolekit import console_process

    proc, url = console_process(tmp_path / "runs")
    context = browser.new_context()
    try:
        page = context.new_page()
        page.goto(url)
        page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                               "&& window.seqrunConsole.statusCount > 1", timeout=30000)
        proc.send_signal(signal.SIGSTOP)
        started = time.monotonic()
        page.wait_for_selector("#lost-banner:not([hidden])", timeout=6000)
        assert time.monotonic() - started < 4.0
        proc.send_signal(signal.SIGCONT)
        page.wait_for_selector("#lost-banner", state="hidden", timeout=10000)
        assert "lost" not in (page.get_attribute("body", "class") or "")
    finally:
        context.close()
        proc.send_signal(signal.SIGCONT)
        proc.kill()
        proc.wait()


def test_one_page_holds_control_the_other_watches_and_takes_it(browser, live, tmp_path):
    """Item 6: any tab could command; now the first holds control, the second watches
    (its commands disabled, STOP not), and takes control explicitly: the first is told."""
    setup, server = live
    tabs = []
    try:
        for _ in range(2):
            context = browser.new_context(viewport={"width": 1500, "height": 1000})
            tab = context.new_page()
            tab.goto(server.url)
            tab.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                                  "&& window.seqrunConsole.control", timeout=20000)
            tabs.append(tab)
        first, second = tabs
        shows(first, "#control-state", "in control")
        shows(second, "#control-state", "watching")
        assert second.is_disabled("#cmd-move") and second.is_disabled("#cmd-arm")
        assert second.is_disabled(".jog-plus[data-joint=j1]")
        assert not second.is_disabled("#stop") and not second.is_disabled("#abort")
        holder = first.evaluate("window.seqrunConsole.client")
        assert holder in second.text_content("#clients")
        second.screenshot(path=str(tmp_path / "watching.png"))
        arm_up(first)
        before = time.perf_counter()
        second.click("#stop")  # a watcher may always STOP
        wait_for(lambda: setup.wire.halts(before), timeout=5)
        second.once("dialog", lambda dialog: dialog.accept())
        second.click("#take-control")
        shows(second, "#control-state", "in control")
        shows(first, "#control-state", "watching")
        first.wait_for_function("document.querySelector('#message').textContent"
                                ".includes('Control taken by page-2')", timeout=5000)
        assert first.is_disabled("#cmd-move") and not second.is_disabled("#cmd-move")
        first.screenshot(path=str(tmp_path / "taken.png"))
    finally:
        for tab in tabs:
            tab.context.close()


def badge_times(page) -> None:
    """Record (epoch ms) when the activity badge shows each text."""
    page.evaluate("""() => {
      window.__badge = [];
      new MutationObserver(() => window.__badge.push([
          document.querySelector('#activity').textContent,
          performance.timeOrigin + performance.now()]))
        .observe(document.querySelector('#activity'),
                 { subtree: true, childList: true, characterData: true });
    }""")


def read_back_times(setup) -> list[float]:
    """Epoch times at which the modules' HALTED was read back (halt_confirmed reached a
    listener of the session: the face's earliest chance to know)."""
    times: list[float] = []
    setup.session.events.add_listener(
        lambda e: times.append(time.time()) if e.type == "halt_confirmed" else None,
        "read-back clock")
    return times


@pytest.mark.parametrize("what", ["move", "run"])
def test_halted_shows_within_100_ms_of_the_read_back(page, live, what):
    """Item 7: after STOP the HALTED badge came 1.27 s (move) / 1.8 s (run) later."""
    setup, _ = live
    (setup.folder / "sequences" / "long_move.yaml").write_text(LONG_MOVE)
    read_back = read_back_times(setup)
    arm_up(page)
    if what == "move":
        page.fill(".move-number[data-joint=j1]", "60")
        page.click("#cmd-move")
        busy = "moving"
    else:
        page.reload()
        page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                               "&& window.seqrunConsole.statusCount > 1", timeout=20000)
        page.click("[data-sequence='long_move.yaml'] button")
        page.wait_for_selector("#seq-verdict.passed", timeout=60000)
        page.click("#run")
        busy = "running"
    wait_for(lambda: (setup.session.status().joints[0].position_deg or 0) > 3, timeout=20)
    shows(page, "#activity", busy)
    badge_times(page)
    page.click("#stop")
    page.wait_for_function("document.querySelector('#activity').textContent === 'halted'",
                           timeout=10000)
    shown = next(t for text, t in page.evaluate("window.__badge") if text == "halted") / 1000
    assert read_back, "no halt_confirmed"
    late = shown - read_back[0]
    # The page draws HALTED from the read-back's own message, not from a later status: the
    # bug drew it 1.27-1.8 s late. The 100 ms goal is a figure of bench/bench_console.py
    # (section 1), measured on an idle host; here, beside the other tests, only the cause.
    assert late < 0.5, f"HALTED shown {late * 1000:.0f} ms after the read-back"


def test_sliders_and_ghost_follow_the_arm_after_a_sequence(page, live):
    """Item 7: after a sequence moved the arm, MOVE's sliders and ghost showed the old
    target."""
    setup, _ = live
    arm_up(page)
    page.fill(".move-number[data-joint=j1]", "10")
    page.click("#cmd-move")
    wait_for(lambda: setup.session.status().activity == "idle"
             and abs(setup.session.status().joints[0].position_deg - 10) < 0.3, timeout=20)
    page.click("[data-sequence='confirm_nudge.yaml'] button")
    page.wait_for_selector("#seq-verdict.passed", timeout=60000)
    page.click("#run")
    page.wait_for_selector("#confirm-dialog:not([hidden])", timeout=20000)
    page.click("#confirm-yes")
    wait_for(lambda: setup.session.status().activity == "idle"
             and abs(setup.session.status().joints[0].position_deg - 3) < 0.3, timeout=30)
    page.wait_for_function("document.querySelector('.move-number[data-joint=j1]').value"
                           " === '3.0'", timeout=5000)
    assert page.evaluate("window.seqrunConsole.view.ghost.group.visible") is False


def test_a_pose_beyond_the_limits_is_no_move_target_and_says_why(page, live):
    from seqrun.arm.poses import pose_document, pose_yaml

    setup, _ = live
    beyond = {"j1": 0, "j2": -90, "j3": 0, "j4": -121, "j5": 0, "j6": 115.74, "j7": 0}
    (setup.folder / "poses" / "beyond.yaml").write_text(
        pose_yaml(pose_document("beyond", setup.arm, beyond, "beyond j4's travel", "manual")),
        encoding="utf-8")
    page.reload()
    page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                           "&& window.seqrunConsole.statusCount > 1", timeout=20000)
    page.wait_for_selector("[data-pose=beyond]", timeout=10000)
    outside = page.locator("[data-pose=beyond]")
    assert outside.is_disabled()
    title = outside.get_attribute("title")
    assert "beyond.yaml" in title and "j4 -121° is outside its limits" in title
    assert not page.locator("[data-pose=totem]").is_disabled()
    # Park's j4 is j4's lower limit (issue 42): the Park button is a move target
    assert not page.locator("[data-pose=park]").is_disabled()


PROBE = """tools:
  - {name: probe, xyz_mm: [0, 0, -300], rpy_deg: [0, 0, 0],
     capsules: [{name: shaft, end_mm: [0, 0, -300], radius_mm: 12}]}
  - {name: pointer, xyz_mm: [40, 0, -150], rpy_deg: [0, 0, 0]}
default_tool: probe
"""


def test_the_3d_view_draws_the_tools_where_the_validator_checks_them(browser, tmp_path):
    """A tool is part of the arm's volume (issue 23): the page draws each tool's capsule
    (a tip line without capsules) in the end-effector frame, at the validator's place."""
    import numpy as np

    from seqrun.arm.kinematics import Chain, frame_transforms

    setup = console_setup(tmp_path, arm_extra=PROBE)
    try:
        with LiveServer(setup.app()) as server:
            context = browser.new_context(viewport={"width": 1200, "height": 900})
            page = context.new_page()
            page.goto(server.url)
            page.wait_for_function("window.seqrunConsole && window.seqrunConsole.ready "
                                   "&& window.seqrunConsole.statusCount > 1", timeout=20000)
            q = [20, -30, 0, 45, -10, 60, 15]
            # Set and read in one task: a status arriving in between would redraw the
            # arm where it really is (seen on a loaded host).
            tools = page.evaluate(f"""(() => {{
                const solid = window.seqrunConsole.view.solid;
                solid.set({q});
                return solid.tools.map((t) => ({{
                    a: t.ends[0].position.toArray(), b: t.ends[1].position.toArray(),
                    r: t.mesh.geometry.parameters.radiusTop}}));
            }})()""")
            context.close()
    finally:
        setup.close()
    flange = frame_transforms(Chain.from_arm(setup.arm), np.radians(q))[-1]

    def at(xyz):
        return (flange @ np.array([*xyz, 1.0]))[:3]

    assert len(tools) == 2
    shaft, pointer = tools
    assert np.allclose(shaft["a"], at([0, 0, 0]), atol=1e-3)
    assert np.allclose(shaft["b"], at([0, 0, -300]), atol=1e-3)
    assert shaft["r"] == 12
    assert np.allclose(pointer["b"], at([40, 0, -150]), atol=1e-3)  # its tip line
