"""The variant designs on the participant screen, in Chromium, to the end of a session.

Pen ids that differ from their profiles (labelled for the participant, varied within a block,
with a recognition and a Likert question) and a pen per condition (unlabelled): the screen loads
each trial's pen by its profile, stores its strokes, and never shows a pen id or a profile name
that the design did not label for the participant (not in a choice, a feedback or an error).
Driven as tests/test_study_browser.py drives study 1 and 2 (its helpers, imported). With
``REALPEN_SHOTS`` set, screenshots of a trial of each variant go to /tmp/shots24/.

The operator console is tested on the same server (one server start for both): at a phone's,
an iPad's and a laptop's widths nothing sticks out of its panel or scrolls sideways, the current
trial and the participant screen's QR code are shown, the sessions filter by design and status,
and a pilot session, an abandoned session and a withdrawal are made from it.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from live_support import serve
from test_study_browser import (
    DESKTOP,
    LANDSCAPE,
    REFUSED,
    Participant,
    api,
    browser,  # noqa: F401  (a fixture)
    browsers,  # noqa: F401  (a fixture)
    likert,
    line,
    open_console,
    participant_url,
    store_rows,
)
from test_study_variants import OWN_PEN, PEN_PER_CONDITION, PROFILE_OF

httpx = pytest.importorskip("httpx")
SHOTS = Path("/tmp/shots24")
# Nothing of these may reach the participant: both designs' pen ids and the profiles they play.
UNSHOWN = re.compile(r"\b(own|bp|pencil|ballpoint)\b", re.I)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A server offering both variant designs, in LAN mode as for tablets."""
    folder = tmp_path_factory.mktemp("variants")
    with serve(folder, "--lan", "--host", "127.0.0.1", "--design", str(OWN_PEN),
               "--design", str(PEN_PER_CONDITION)) as served:
        served.store = folder / "strokes.sqlite3"
        with httpx.Client(timeout=10, headers={"Authorization": f"Bearer {served.token}"}) as client:
            served.client = client
            yield served


def shown(page) -> str:
    """Everything on the participant screen's page, hidden parts too (they may be shown)."""
    return page.evaluate("document.body.textContent")


def assert_no_pen_named(page, when: str) -> None:
    found = UNSHOWN.findall(shown(page))
    assert not found, f"{when}: the participant screen names {found}"


def screenshot(page, name: str) -> None:
    if os.environ.get("REALPEN_SHOTS"):
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / name))


def run_session(server, tablet, design: str, participant: str) -> tuple[int, Participant]:
    """A whole session of ``design`` on the participant screen; returns its id and screen."""
    created = api(server, "POST", "/api/sessions", {"design": design, "participant": participant})
    assert created.status_code == 201, created.text
    session, total = created.json()["session"], created.json()["trials"]
    page = tablet.context.new_page()
    page.goto(participant_url(server, session))
    screen = Participant(page)
    screen.start()
    for n in range(1, total + 1):
        trial = screen.trial(n)
        # The profile is what plays; the page knows the pen's id only to leave it unshown.
        assert screen.eval("realpen.pen") == trial["profile"] == PROFILE_OF[trial["pen"]]
        assert_no_pen_named(page, f"{design} trial {n}")
        screen.stroke(line(0.15, 0.3, 0.7, 0.3, 5))
        page.click("#done")
        for question in trial["questions"]:
            if question["type"] == "likert":
                likert(page, question["id"], 4)
        choices = [q for q in trial["questions"] if q["type"] == "choice"]
        if choices:
            buttons = page.locator(f".question[data-id={choices[0]['id']}] button")
            assert buttons.all_inner_texts() == ["Pen A", "Pen B"]  # the labels, never the ids
        if trial["phase"] == "experimental":
            assert_no_pen_named(page, f"{design} trial {n}, answering")
            screenshot(page, f"participant-{design}-trial.png")
        if choices:
            page.click(f".question[data-id={choices[0]['id']}] "
                       f"button[data-value={trial['pen']}]")
        if len(trial["questions"]) > 1 or not choices:
            page.click("#next")
        if trial["feedback"]:
            screen.wait("() => realpen.study.screen === 'feedback'")
            label = {"own": "Pen A", "bp": "Pen B"}[trial["pen"]]
            assert page.locator("#screen-text").inner_text() == f"It was {label}."
            assert_no_pen_named(page, f"{design} trial {n}, feedback")
            screenshot(page, f"participant-{design}-feedback.png")
            page.click("#continue")
    screen.wait("() => realpen.study.screen === 'done'")
    screen.settle()
    assert screen.eval("realpen.link.errors") == 0  # every stroke's pen and trial taken
    assert_no_pen_named(page, f"{design} done")
    return session, screen


def test_both_variant_designs_run_to_the_end_and_name_no_pen(server, browsers):  # noqa: F811
    tablet = browsers(LANDSCAPE)
    for design, participant in (("own-pen", "P01"), ("pen-per-condition", "P02")):
        session, _ = run_session(server, tablet, design, participant)
        progress = api(server, "GET", f"/api/sessions/{session}").json()
        assert (progress["state"], progress["answered"]) == ("finished", progress["trials"])
        # Strokes went out under the profile; trials and answers keep the pen's id.
        strokes = store_rows(server, "SELECT t.pen, s.pen, s.modality FROM strokes s JOIN trials t "
                                     "ON t.session_id = s.study_session AND t.n = s.trial WHERE "
                                     "s.study_session = ?", session)
        assert len(strokes) == progress["trials"]
        expected = "audio-tactile" if design == "own-pen" else "tactile"
        assert all(stroke == PROFILE_OF[pen] and modality == expected
                   for pen, stroke, modality in strokes)
    assert store_rows(server, "SELECT DISTINCT answer FROM answers WHERE question = 'which' "
                              "ORDER BY answer") == [("bp",), ("own",)]
    assert tablet.problems == []

    # A trial whose pen cannot be loaded stops the session with words that name no pen (the
    # server's reason names the profile: the browser's console has it, the screen does not).
    session = api(server, "POST", "/api/sessions", {"design": "pen-per-condition",
                                                    "participant": "P03"}).json()["session"]
    page = tablet.context.new_page()
    refusal = {"detail": "trial 1: the pen profile 'pencil' is not offered by this server"}
    page.route(re.compile(rf"/api/sessions/{session}/trials/1/tactile\.wav"),
               lambda route: route.fulfill(status=404, json=refusal))
    page.goto(participant_url(server, session))
    screen = Participant(page)
    screen.start()
    screen.wait("() => realpen.study.screen === 'error'")
    assert page.locator("#screen-text").inner_text() == (
        "This trial's pen could not be loaded. Please let the experimenter know.")
    assert_no_pen_named(page, "an unloadable pen")
    screenshot(page, "participant-pen-unavailable.png")
    assert set(tablet.problems) == {REFUSED.format(404, "Not Found")}


# ---- the operator console ------------------------------------------------------------------

WIDTHS = {375: 812, 768: 1024, 1024: 768, 1366: 900}  # phone, iPad portrait and landscape, laptop

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


def start(server, design: str, participant: str, **fields) -> dict:
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
