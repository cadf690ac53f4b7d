"""The operator console in Chromium at a phone's, an iPad's and a laptop's widths: nothing sticks
out of its panel or scrolls sideways, the current trial and the participant screen's QR code are
shown, the sessions filter by design and status, and a pilot session, an abandoned session and
a withdrawal are made from it.

The fixtures are test_study_browser.py's (a ``realpen serve --lan`` subprocess and Debian's
Chromium through Playwright). With ``REALPEN_SHOTS`` set, a screenshot of each width goes to
/tmp/shots24/.
"""

from __future__ import annotations

import os
from pathlib import Path

from test_study_browser import (
    DESKTOP,
    api,
    browser,  # noqa: F401  (a fixture)
    browsers,  # noqa: F401  (a fixture)
    open_console,
    server,  # noqa: F401  (a fixture)
)

WIDTHS = {375: 812, 768: 1024, 1024: 768, 1366: 900}  # phone, iPad portrait and landscape, laptop
SHOTS = Path("/tmp/shots24")

# Whether the page scrolls sideways, and every element of a console panel that sticks out of it
# (or a panel out of the window), as "tag#id.class: left-right outside left-right".
OVERFLOW = """() => {
  const out = [];
  const fits = (inner, outer) => inner.left >= outer.left - 0.5 && inner.right <= outer.right + 0.5;
  const view = { left: 0, right: window.innerWidth };
  for (const panel of document.querySelectorAll('.op-main .panel')) {
    const box = panel.getBoundingClientRect();
    if (!fits(box, view)) out.push(`panel ${panel.id}: outside the window`);
    for (const node of panel.querySelectorAll('*')) {
      const r = node.getBoundingClientRect();
      if ((r.width || r.height) && !fits(r, box)) {
        const span = (b) => `${b.left.toFixed(0)}-${b.right.toFixed(0)}`;
        out.push(`${node.tagName.toLowerCase()}#${node.id}.${node.className}: `
          + `${span(r)} outside ${span(box)}`);
      }
    }
  }
  return { scroll: document.documentElement.scrollWidth, width: window.innerWidth, out };
}"""


def start(server, design: str, participant: str, **fields) -> dict:  # noqa: F811
    reply = api(server, "POST", "/api/sessions", {"design": design, "participant": participant,
                                                  "consent": True, **fields})
    assert reply.status_code == 201, reply.text
    return reply.json()


def test_the_console_fits_every_width_and_runs_the_sessions(server, browsers):  # noqa: F811
    running = start(server, "study2", "P03-a-participant-code-of-some-length", site="Lab A")
    paused = start(server, "study2", "P02")
    api(server, "POST", f"/api/sessions/{paused['session']}/state", {"state": "paused"})
    finished = start(server, "study1", "P04")
    api(server, "POST", f"/api/sessions/{finished['session']}/state", {"state": "finished"})
    session = running["session"]

    operator_side = browsers(DESKTOP)
    console = open_console(operator_side, f"{server.base}study?token={server.token}#session={session}")
    console.wait_for_function("() => realpenStudy.progress && realpenStudy.progress.current")
    current = console.evaluate("realpenStudy.progress.current")
    assert current == running["current"] and current["n"] == 1
    # The current trial: where it is in the plan, and what it plays (the console may name pens).
    assert console.locator("#now-trial").inner_text() == f"1 of {current['of']} · {current['phase']}"
    assert console.locator("#now-block").inner_text() == \
        f"{current['block']} · trial 1 of {current['block_of']}"
    assert console.locator("#now-pen").inner_text() == current["pen"]  # its profile is its id
    row = console.locator(f"#sessions tbody tr[data-session='{session}']")
    assert row.locator("td[data-label='Current trial']").inner_text().startswith(
        f"1 of {current['of']} · {current['block']}")
    # The participant screen's QR code, loaded from the server beside its address.
    qr = console.locator("#participant-qr")
    console.wait_for_function("() => document.getElementById('participant-qr').naturalWidth > 0")
    assert qr.get_attribute("src").startswith(f"/api/sessions/{session}/participant-qr.svg")
    assert qr.bounding_box()["width"] >= 200  # large enough for a tablet's camera

    for width, height in WIDTHS.items():
        console.set_viewport_size({"width": width, "height": height})
        console.evaluate("() => new Promise((done) => requestAnimationFrame(() => "
                         "requestAnimationFrame(done)))")
        layout = console.evaluate(OVERFLOW)
        assert layout["scroll"] <= layout["width"], (width, layout)
        assert layout["out"] == [], (width, layout["out"])
        assert console.locator("#cur-trial").is_visible()
        assert qr.bounding_box()["width"] >= 200 or width < 400
        if os.environ.get("REALPEN_SHOTS"):
            SHOTS.mkdir(parents=True, exist_ok=True)
            console.screenshot(path=str(SHOTS / f"console-{width}px.png"), full_page=True)
    console.set_viewport_size(DESKTOP)

    # The sessions by status and by design, with counts.
    console.click("#filter-state button[data-status='paused']")
    assert console.evaluate("realpenStudy.visible") == [paused["session"]]
    assert console.locator("#filter-state button[data-status='paused'] b").inner_text() == "1"
    console.click("#filter-state button[data-status='paused']")  # pressed again: all
    console.select_option("#filter-design", "study1")
    assert console.evaluate("realpenStudy.visible") == [finished["session"]]
    assert console.locator("#filter-design option:checked").inner_text().endswith("(1)")
    console.select_option("#filter-design", "")

    # A pilot session, made from the form: it takes no plan row.
    console.select_option("#design", "study1")
    console.fill("#participant", "pilot-1")
    console.check("#consent")
    console.check("#pilot")
    console.click("#start")
    console.wait_for_function("() => /^Pilot session/.test("
                              "document.getElementById('form-note').textContent)")
    pilot = console.evaluate("realpenStudy.progress")
    assert pilot["pilot"] is True and console.locator("#cur-pilot").is_visible()
    console.wait_for_function("() => realpenStudy.sessions.some((p) => p.pilot)")
    console.click("#filter-state button[data-status='pilot']")
    assert console.evaluate("realpenStudy.visible") == [pilot["session"]]
    console.click("#filter-state button[data-status='pilot']")

    # The pilot ends as abandoned (after a confirmation): no current trial any more.
    console.click("#abandon")
    console.click("#abandon-confirm")
    console.wait_for_function("() => realpenStudy.progress.state === 'abandoned'")
    assert console.locator("#cur-trial").is_hidden() and console.locator("#abandon").is_disabled()

    # Withdrawing asks for the participant's ID, typed exactly.
    console.click(f"#sessions tbody tr[data-session='{paused['session']}']")
    console.wait_for_function(f"() => realpenStudy.progress.session === {paused['session']}")
    console.click("#withdraw")
    assert "deleted" in console.locator("#withdraw-text").inner_text()
    console.fill("#withdraw-code", "P2")
    assert console.locator("#withdraw-confirm").is_disabled()
    console.fill("#withdraw-code", "P02")
    console.click("#withdraw-confirm")
    console.wait_for_function(f"() => realpenStudy.sessions.some((p) => p.session === "
                              f"{paused['session']} && p.state === 'withdrawn')")
    assert console.locator("#withdraw-dialog").is_hidden()
    assert operator_side.problems == []
