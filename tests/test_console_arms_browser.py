"""The console of two arms in a real browser (Chromium via Playwright, as
tests/test_console_browser.py) on two arm sessions over built-in simulators: one 3D view
with both arms where their bases put them, a telemetry panel per arm, one STOP for both
that shows each arm's outcome, commands that go to the selected arm only."""

from __future__ import annotations

import time

import numpy as np
import pytest
from armsconsolekit import TWO_ARMS, arms_setup
from consolekit import LiveServer, wait_for
from test_console_browser import PROBE, browser  # noqa: F401 (the fixture)

pytestmark = pytest.mark.slow  # a browser, a server and real-time arms

B_SILENT = {"B": ["all:drop_acks=1.0@0"]}


def open_page(browser, server, tmp_path, name: str):  # noqa: F811
    context = browser.new_context(viewport={"width": 1500, "height": 1000})
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(f"{e} {getattr(e, 'stack', '')}"))
    page.goto(server.url)
    page.wait_for_function("window.seqrunArms && window.seqrunArms.ready "
                           "&& window.seqrunArms.statusCount > 2", timeout=20000)
    page.errors = errors  # type: ignore[attr-defined]
    page.shot = lambda: page.screenshot(path=str(tmp_path / f"{name}.png"),  # type: ignore
                                        full_page=True)
    return context, page


#: Arm B carries a probe (its own arm file): the view draws each arm's tools.
WITH_PROBE = TWO_ARMS.replace('[arms.B]\narm = "lwa3"', '[arms.B]\narm = "lwa3_probe"')


@pytest.fixture
def served(tmp_path, request):
    faults = getattr(request, "param", None)
    setup = arms_setup(tmp_path, faults=faults, campaign=WITH_PROBE,
                       arm_files={"lwa3_probe": PROBE})
    with LiveServer(setup.app()) as server:
        yield setup, server
    setup.close()


@pytest.fixture
def plain(tmp_path):
    """Two LWA 3 without tools (the probe's tip lies below the desk guard at Park, where
    a jog is refused)."""
    setup = arms_setup(tmp_path)
    with LiveServer(setup.app()) as server:
        yield setup, server
    setup.close()


def badge(page, arm: str) -> str:
    return page.text_content(f"#arm-{arm} .activity") or ""


def test_both_arms_in_one_view_where_their_bases_put_them(browser, served, tmp_path):  # noqa: F811
    setup, server = served
    context, page = open_page(browser, server, tmp_path, "two-arms")
    try:
        assert page.locator(".arm-panel").count() == 2
        page.wait_for_function("document.querySelector('#arm-B .pos') && "
                               "document.querySelector('#arm-B .pos').textContent !== ''")
        assert page.text_content("#tlm-A-j2 .pos") == "-90.00"  # Park
        assert page.text_content("#tlm-B-j2 .pos") == "-90.00"
        # each figure, drawn at a pose, is FK of that pose carried by the arm's base
        from seqrun.arm.kinematics import Chain, frame_transforms

        for arm_id, q in (("A", [20, -30, 0, 45, -10, 60, 15]),
                          ("B", [-35, -60, 10, 80, 20, -40, 5])):
            drawn = page.evaluate("""([id, q]) => {
                const f = window.seqrunArms.view.figures[id];
                f.figure.set(q);
                f.holder.updateMatrixWorld(true);
                const tcp = f.figure.tcp.matrixWorld.elements;   // column-major
                const joints = f.figure.joints.map((m) => {
                    const e = m.matrixWorld.elements; return [e[12], e[13], e[14]]; });
                return {tcp, joints};
            }""", [arm_id, q])
            session = setup.sessions[arm_id]
            fk = frame_transforms(Chain.from_arm(session.arm), np.radians(q))
            base = setup.contexts[arm_id].base_transform()
            expected_tcp = base @ fk[-1]
            tcp = np.array(drawn["tcp"]).reshape(4, 4).T
            np.testing.assert_allclose(tcp, expected_tcp, atol=1e-6)
            for k, point in enumerate(drawn["joints"]):
                np.testing.assert_allclose(point, (base @ fk[k])[:3, 3], atol=1e-6)
            tools = page.evaluate("""(id) => window.seqrunArms.view.figures[id].figure.tools
                .map((t) => t.ends.map((e) => { const m = e.matrixWorld.elements;
                                               return [m[12], m[13], m[14]]; }))""", arm_id)
            if arm_id == "A":
                assert tools == []  # A carries no tool
            else:  # B's probe: its shaft and the pointer's tip line, in the facility frame
                def at(xyz):
                    return (base @ fk[-1] @ np.array([*xyz, 1.0]))[:3]

                assert len(tools) == 2
                np.testing.assert_allclose(tools[0][1], at([0, 0, -300]), atol=1e-3)
                np.testing.assert_allclose(tools[1][1], at([40, 0, -150]), atol=1e-3)
        # B stands 900 mm along y, turned: its figure's base is there, not at A's
        b_base = page.evaluate("window.seqrunArms.view.figures.B.holder.matrixWorld.elements")
        assert b_base[13] == pytest.approx(900)
        # each labelled with its id, the tools of each drawn (the arm file's)
        assert page.evaluate("Object.keys(window.seqrunArms.view.figures)") == ["A", "B"]
        page.evaluate("window.seqrunArms.view.dirty = true; window.seqrunArms.view.render()")
        from test_console_browser import distinct_colours

        assert distinct_colours(page.locator("#view3d canvas").screenshot()) > 40
        page.shot()
        assert not page.errors, page.errors
    finally:
        context.close()


def test_one_stop_halts_both_and_each_panel_says_halted(browser, served, tmp_path):  # noqa: F811
    setup, server = served
    context, page = open_page(browser, server, tmp_path, "stop-both")
    try:
        before = time.perf_counter()
        page.dispatch_event("#stop", "pointerdown", {"button": 0})
        wait_for(lambda: setup.wires["A"].halts(before) and setup.wires["B"].halts(before), 5)
        page.wait_for_function("document.querySelector('#arm-A .activity').textContent === "
                               "'halted' && document.querySelector('#arm-B .activity')"
                               ".textContent === 'halted'", timeout=10000)
        assert "every arm halted" in page.text_content("#message")
        assert page.locator(".stop-line:visible").count() == 0
        page.shot()
        assert not page.errors, page.errors
    finally:
        context.close()


@pytest.mark.parametrize("served", [B_SILENT], indirect=True)
def test_an_arm_that_does_not_confirm_says_stop_failed_and_greys(browser, served,  # noqa: F811
                                                                   tmp_path):
    setup, server = served
    context, page = open_page(browser, server, tmp_path, "stop-b-silent")
    try:
        # B's modules are silent: contact with B is lost (its status stale), A is fine
        page.wait_for_function("document.querySelector('#arm-B').classList.contains('lost-arm')",
                               timeout=15000)
        assert "lost-arm" not in (page.get_attribute("#arm-A", "class") or "")
        assert page.evaluate("window.seqrunArms.view.figures.B.lost") is True
        assert page.evaluate("window.seqrunArms.view.figures.A.lost") is False
        before = time.perf_counter()
        page.keyboard.press("Escape")
        page.wait_for_function("document.querySelector('#arm-B .activity').textContent === "
                               "'STOP FAILED'", timeout=20000)
        assert setup.wires["A"].halts(before) and setup.wires["B"].halts(before)
        assert badge(page, "A") == "halted"
        line = page.text_content("#arm-B .stop-line")
        assert line.startswith("STOP FAILED for arm B") and "NOT confirmed" in line
        assert not page.is_visible("#arm-A .stop-line")
        message = page.text_content("#message")
        assert "STOP FAILED for arm B" in message and "arm A" not in message
        page.shot()
        assert not page.errors, page.errors
    finally:
        context.close()


def test_commands_go_to_the_selected_arm_only(browser, plain, tmp_path):  # noqa: F811
    setup, server = plain
    context, page = open_page(browser, server, tmp_path, "select-b")
    try:
        page.wait_for_function("document.querySelector('#control-state').textContent"
                               ".includes('this page')")
        page.click(".arm-choice[data-arm=B]")
        page.wait_for_function("document.querySelector('#poses [data-pose=totem]')")
        a_count, b_count = len(setup.wires["A"].frames), len(setup.wires["B"].frames)
        page.click("#cmd-reset")
        page.wait_for_function("document.querySelector('#message').textContent"
                               ".startsWith('arm B: Reset')", timeout=15000)

        def commands(arm: str, since: int) -> list[bytes]:
            return [data for _, _, data, _ in setup.wires[arm].frames[since:]
                    if data and data[0] != 0x0A]  # anything but a read

        assert commands("B", b_count), "B got no Reset"
        assert not commands("A", a_count), "A was commanded"
        # Arm, Home, then a held jog button: B moves, A is never commanded
        for button, label in (("#cmd-arm", "Arm"), ("#cmd-home", "Home")):
            page.evaluate("document.querySelector('#message').textContent = ''")
            page.click(button)
            page.wait_for_function(f"document.querySelector('#message').textContent"
                                   f".startsWith('arm B: {label}')", timeout=20000)
            assert "error" not in (page.get_attribute("#message", "class") or ""), \
                page.text_content("#message")
        before = time.perf_counter()
        jog = page.locator("[data-jog='j1+']")
        jog.hover()
        page.mouse.down()
        time.sleep(0.8)
        page.mouse.up()
        wait_for(lambda: setup.sessions["B"].status().activity != "jogging", 5)
        assert setup.wires["B"].motions(before) > 0, (page.evaluate("window.seqrunArms.lastReplies"), page.text_content("#message"))
        assert setup.wires["A"].motions(before) == 0 and not commands("A", a_count)
        assert setup.sessions["B"].status().joints[0].position_deg > 0.2
        assert abs(setup.sessions["A"].status().joints[0].position_deg) < 1e-6
        assert not page.errors, page.errors
    finally:
        context.close()


def test_a_two_arm_sequence_runs_from_the_page(browser, plain, tmp_path):  # noqa: F811
    from test_console_arms_api import BOTH_NUDGE

    setup, server = plain
    (setup.folder / "sequences" / "both_nudge.yaml").write_text(BOTH_NUDGE)
    context, page = open_page(browser, server, tmp_path, "run-both")
    try:
        page.wait_for_function("document.querySelector('#control-state').textContent"
                               ".includes('this page')")
        page.select_option("#sequence", "both_nudge.yaml")
        page.click("#run")
        page.wait_for_selector("#confirm-dialog:not([hidden])", timeout=30000)
        assert "Is the floor between the arms clear?" in page.text_content("#confirm-text")
        page.click("#confirm-yes")
        page.wait_for_function("document.querySelector('#run-state').textContent"
                               ".includes('ended')", timeout=60000)
        assert "exit 0" in page.text_content("#run-state"), page.text_content("#run-state")
        log = page.text_content("#events")
        assert "[A]" in log and "[B]" in log and "A nudges j1" in log and "B nudges j1" in log
        assert setup.sessions["B"].status().joints[0].position_deg == pytest.approx(-3, abs=0.3)
        # Past runs: the run of both, a link to each arm's part (its own report)
        page.wait_for_function("(() => { const li = document.querySelector('#runs li'); "
                               "return li && li.textContent.includes('Both nudge passed') "
                               "&& li.querySelectorAll('a').length === 2; })()", timeout=20000)
        parts = page.eval_on_selector_all("#runs li:first-child a",
                                          "links => links.map(a => [a.textContent, a.href])")
        assert [text for text, _ in parts] == ["arm A", "arm B"], parts
        for (text, href), arm in zip(parts, "AB"):
            assert f"/api/v1/arms/{arm}/runs/" in href and href.endswith(f"/{arm}/report.html")
            assert page.request.get(href).status == 200
        page.shot()
        assert not page.errors, page.errors
    finally:
        context.close()


def test_move_allvel_and_gripper_act_on_the_selected_arm(browser, plain, tmp_path):  # noqa: F811
    """The one-arm page's MOVE sliders, ALLVEL boxes and gripper panel (the same module,
    static/controls.js) on the page of several arms, for the selected arm only."""
    setup, server = plain
    # a part between B's jaws only (each arm's simulator has the arm file's gripper)
    setup.sessions["B"].connection.bus.inner.arm.module(8).part_m = 0.040
    context, page = open_page(browser, server, tmp_path, "move-b")
    try:
        page.wait_for_function("document.querySelector('#control-state').textContent"
                               ".includes('this page')")
        page.click(".arm-choice[data-arm=B]")
        for button, label in (("#cmd-arm", "Arm"), ("#cmd-home", "Home")):
            page.evaluate("document.querySelector('#message').textContent = ''")
            page.click(button)
            page.wait_for_function(f"document.querySelector('#message').textContent"
                                   f".startsWith('arm B: {label}')", timeout=20000)
        a_velocities = setup.sessions["A"].move_velocities()
        page.fill(".vel-box[data-joint=j1]", "6")
        page.click("#cmd-allvel")
        page.wait_for_function("document.querySelector('#message').textContent"
                               ".startsWith('arm B: ALLVEL')", timeout=10000)
        assert setup.sessions["B"].move_velocities()["j1"] == 6
        assert setup.sessions["A"].move_velocities() == a_velocities
        # MOVE: the slider's target for B's j1; A is never commanded
        a_count = len(setup.wires["A"].frames)
        before = time.perf_counter()
        page.fill(".move-number[data-joint=j1]", "4")
        assert page.input_value(".move-slider[data-joint=j1]") == "4"
        page.click("#cmd-move")
        wait_for(lambda: abs(setup.sessions["B"].status().joints[0].position_deg - 4) < 0.05
                 and setup.sessions["B"].status().activity in ("idle", None), 20)
        assert setup.wires["B"].motions(before) > 0
        assert setup.wires["A"].motions(before) == 0
        assert not [data for _, _, data, _ in setup.wires["A"].frames[a_count:]
                    if data and data[0] != 0x0A], "arm A was commanded"
        # the gripper panel is B's: its state read, Grip goes to B's gripper
        page.wait_for_function("document.querySelector('#gripper-state').textContent"
                               ".includes('mm open')", timeout=10000)
        assert page.is_visible("#gripper-panel")
        page.fill("#grip-width", "40")
        page.fill("#grip-force", "50")
        page.click("#cmd-grip")
        page.wait_for_function("document.querySelector('#gripper-state').textContent"
                               ".includes('holding a part')", timeout=20000)
        assert not [data for _, _, data, _ in setup.wires["A"].frames[a_count:]
                    if data and data[0] != 0x0A], "arm A was commanded"
        # selecting A: the sliders are A's (where A stands), the gripper panel A's (open)
        page.click(".arm-choice[data-arm=A]")
        page.wait_for_function("document.querySelector('.move-number[data-joint=j1]')"
                               ".value === '0.0'", timeout=5000)
        page.wait_for_function("document.querySelector('#gripper-state').textContent"
                               ".startsWith('70.0 mm open, not holding')", timeout=10000)
        page.shot()
        assert not page.errors, page.errors
    finally:
        context.close()


def test_a_one_arm_sequence_runs_on_the_selected_arm_and_is_listed(browser, plain,  # noqa: F811
                                                                   tmp_path):
    """A sequence of one arm runs on the arm selected (as ``seqrun run --arm-id B``), the
    other arm is never commanded; Past runs lists it as B's, its report behind its link."""
    setup, server = plain
    context, page = open_page(browser, server, tmp_path, "run-one-arm")
    try:
        page.wait_for_function("document.querySelector('#control-state').textContent"
                               ".includes('this page')")
        assert "(one arm: the selected)" in page.inner_text(
            "#sequence option[value='confirm_nudge.yaml']")
        page.click(".arm-choice[data-arm=B]")
        a_count = len(setup.wires["A"].frames)
        page.select_option("#sequence", "confirm_nudge.yaml")
        page.click("#run")
        page.wait_for_selector("#confirm-dialog:not([hidden])", timeout=30000)
        assert page.text_content("#confirm-text").startswith("arm B asks: Is the space")
        assert page.text_content("#run-state").startswith("arm B: confirm_nudge.yaml ")
        page.click("#confirm-yes")
        wait_for(lambda: abs(setup.sessions["B"].status().joints[0].position_deg - 3) < 0.05
                 and setup.sessions["B"].status().activity in ("idle", None), 30)
        assert not [data for _, _, data, _ in setup.wires["A"].frames[a_count:]
                    if data and data[0] != 0x0A], "arm A was commanded"
        page.wait_for_function("[...document.querySelectorAll('#runs li a')].some(a => "
                               "a.textContent.includes('Confirm then nudge passed') "
                               "&& a.href.endsWith('/report.html'))", timeout=20000)
        link = page.locator("#runs li a", has_text="(arm B)").first
        href = link.get_attribute("href") or ""
        assert "/api/v1/arms/B/runs/" in href and href.endswith("/report.html"), href
        assert page.request.get(server.url.rstrip("/") + href).status == 200
        page.shot()
        assert not page.errors, page.errors
    finally:
        context.close()
