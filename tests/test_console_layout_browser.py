"""Nothing on the console's pages sits under STOP, at any window size down to 1280x720, the
page of one arm and the page of several, however far the panels are scrolled (Chromium via
Playwright, as tests/test_console_browser.py). STOP is fixed on top of everything: what
scrolls under it would be hidden (arm A's name and badge were, at 1400x900, once the events
list had scrolled the page). Screenshots of every size are left in the test's tmp folder."""

from __future__ import annotations

import pytest
from armsconsolekit import arms_setup
from consolekit import LiveServer, console_setup
from test_console_browser import browser  # noqa: F401 (the fixture)

pytestmark = pytest.mark.slow  # a browser, servers and the simulated arms in real time

SIZES = [(1920, 1080), (1600, 900), (1400, 900), (1366, 768), (1280, 800), (1280, 720)]

#: Every visible element that paints something (text of its own, a control or canvas, a
#: background or a border; not a bare layout box), its box clipped by the ancestors that
#: clip it (overflow) and by the window, that meets STOP's box: [name, box, text] (STOP
#: itself, its ancestors and the bar's background it is meant to stand on left out).
UNDER_STOP = r"""() => {
  const stop = document.querySelector('#stop').getBoundingClientRect();
  const meets = (r) => r.width > 0 && r.height > 0 && r.left < stop.right
    && r.right > stop.left && r.top < stop.bottom && r.bottom > stop.top;
  const clip = (r, c) => ({left: Math.max(r.left, c.left), top: Math.max(r.top, c.top),
    right: Math.min(r.right, c.right), bottom: Math.min(r.bottom, c.bottom),
    get width() { return this.right - this.left; }, get height() { return this.bottom - this.top; }});
  const found = [];
  for (const e of document.querySelectorAll('body *')) {
    if (e.id === 'stop' || e.id === 'bar' || e.contains(document.querySelector('#stop'))) continue;
    if (!e.checkVisibility({checkVisibilityCSS: true})) continue;
    const s = getComputedStyle(e);
    const paints = [...e.childNodes].some((n) => n.nodeType === 3 && n.textContent.trim())
      || ['BUTTON', 'INPUT', 'SELECT', 'TEXTAREA', 'CANVAS', 'IMG', 'svg'].includes(e.tagName)
      || !/rgba\(0, 0, 0, 0\)|transparent/.test(s.backgroundColor) || s.backgroundImage !== 'none'
      || ['Top', 'Right', 'Bottom', 'Left'].some((k) => parseFloat(s['border' + k + 'Width']) > 0);
    if (!paints) continue;
    let r = clip(e.getBoundingClientRect(), {left: 0, top: 0, right: innerWidth, bottom: innerHeight});
    for (let a = e.parentElement; a && a !== document.body; a = a.parentElement) {
      const s = getComputedStyle(a);
      if (s.overflowX !== 'visible' || s.overflowY !== 'visible') r = clip(r, a.getBoundingClientRect());
    }
    if (meets(r)) found.push([e.tagName.toLowerCase() + (e.id ? '#' + e.id : '')
      + (e.className && typeof e.className === 'string' ? '.' + e.className.split(' ').join('.') : ''),
      [r.left, r.top, r.right, r.bottom].map(Math.round), (e.textContent || '').slice(0, 40)]);
  }
  return found;
}"""

#: Every way the page's content can be scrolled: the page itself and every scroll box.
SCROLL_TO = """(fraction) => {
  window.scrollTo(0, fraction * document.documentElement.scrollHeight);
  for (const e of document.querySelectorAll('*')) {
    if (e.scrollHeight > e.clientHeight) e.scrollTop = fraction * (e.scrollHeight - e.clientHeight);
  }
}"""


@pytest.fixture(params=["one arm", "two arms"])
def served(request, tmp_path):
    setup = console_setup(tmp_path) if request.param == "one arm" else arms_setup(tmp_path)
    with LiveServer(setup.app()) as server:
        yield request.param, server
    setup.close()


def test_nothing_sits_under_stop_at_any_size_or_scroll(browser, served, tmp_path):  # noqa: F811
    kind, server = served
    ready = ("window.seqrunConsole && window.seqrunConsole.ready" if kind == "one arm"
             else "window.seqrunArms && window.seqrunArms.ready "
                  "&& window.seqrunArms.statusCount > 2")
    context = browser.new_context(viewport={"width": SIZES[0][0], "height": SIZES[0][1]})
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.goto(server.url)
        page.wait_for_function(ready, timeout=20000)
        page.wait_for_function("document.querySelectorAll('#events li').length >= 2",
                               timeout=10000)  # events arrived (they once scrolled the page)
        # a long message in the bar: it ends before STOP, cut with an ellipsis
        page.evaluate("document.querySelector('#message').textContent = 'x '.repeat(400)")
        problems = {}
        for width, height in SIZES:
            page.set_viewport_size({"width": width, "height": height})
            for fraction in (0.0, 0.5, 1.0):
                page.evaluate(SCROLL_TO, fraction)
                page.wait_for_timeout(50)
                under = page.evaluate(UNDER_STOP)
                if under:
                    problems[f"{width}x{height} scrolled {fraction:.0%}"] = under
            page.evaluate(SCROLL_TO, 0.0)
            page.screenshot(path=str(tmp_path / f"{kind.replace(' ', '-')}-{width}x{height}.png"))
        assert not problems, problems
        # STOP stays whole inside the window at the smallest size
        box = page.locator("#stop").bounding_box()
        assert box["x"] >= 0 and box["x"] + box["width"] <= 1280 and box["y"] >= 0
        assert not errors, errors
    finally:
        context.close()
