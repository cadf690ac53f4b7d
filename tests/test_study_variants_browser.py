"""The variant designs on the participant screen, in Chromium, to the end of a session.

Pen ids that differ from their profiles (labelled for the participant, varied within a block,
with a recognition and a Likert question) and a pen per condition (unlabelled): the screen loads
each trial's pen by its profile, stores its strokes, and never shows a pen id or a profile name
that the design did not label for the participant (not in a choice, a feedback or an error).
Driven as tests/test_study_browser.py drives study 1 and 2 (its helpers, imported). With
``REALPEN_SHOTS`` set, screenshots of a trial of each variant go to /tmp/shots24/.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from live_support import serve
from test_study_browser import (
    LANDSCAPE,
    REFUSED,
    Participant,
    api,
    browser,  # noqa: F401  (a fixture)
    browsers,  # noqa: F401  (a fixture)
    likert,
    line,
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
