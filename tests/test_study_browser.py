"""The study pages in a real browser: the operator console and the participant screen.

Debian's Chromium driven by Playwright for Python against a real ``realpen serve`` subprocess
(as in test_live_browser.py). Pen strokes are trusted pen events injected through the DevTools
protocol; answers are taps on the participant screen's buttons. The tests then read what the
server stored: the progress through the API, the trials, answers and strokes in the SQLite
store, and the export (:func:`realpen.study.export.export_trials`). Screenshots of both pages
go to ``test-artifacts/`` (git-ignored).
"""

from __future__ import annotations

import csv
import json
import math
import sqlite3
import time
from pathlib import Path

import pytest
from live_support import CHROMIUM, CHROMIUM_ARGS, CHROMIUM_MISSING, serve

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"
LANDSCAPE = {"width": 1180, "height": 820}
PORTRAIT = {"width": 820, "height": 1180}
DESKTOP = {"width": 1280, "height": 900}
# Chromium reports every request that failed on the network as a console error: the tests that
# cut the network on purpose expect these, and only these.
NETWORK_FAILURE = "Failed to load resource: net::ERR_FAILED"
# It reports a 4xx reply as one too: the tests that provoke one expect it.
REFUSED = "Failed to load resource: the server responded with a status of {} ({})"
UNPROCESSABLE = REFUSED.format(422, "Unprocessable Entity")
CONFLICT = REFUSED.format(409, "Conflict")

if not CHROMIUM.exists():
    pytest.skip(CHROMIUM_MISSING, allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
httpx = pytest.importorskip("httpx")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """One server for the module, in LAN mode (as for tablets): every page and request needs
    its token (the pages get it from their URL, the tests' API calls send it as a bearer)."""
    folder = tmp_path_factory.mktemp("study")
    with serve(folder, "--lan", "--host", "127.0.0.1") as served:
        served.store = folder / "strokes.sqlite3"
        with httpx.Client(timeout=10, headers={"Authorization": f"Bearer {served.token}"}) as client:
            served.client = client  # one connection, kept alive
            yield served


@pytest.fixture
def browser(chromium):
    return chromium(CHROMIUM_ARGS)


class Browser:
    """One browser context (a tablet, or the operator's computer) and what went wrong in it:
    uncaught errors and console errors (CSP violations are console errors) of all its pages."""

    def __init__(self, browser, viewport=LANDSCAPE):
        self.context = browser.new_context(viewport=viewport)
        self.context.set_default_timeout(15_000)
        self.problems: list[str] = []
        self.context.on("weberror", lambda error: self.problems.append(str(error.error)))
        self.context.on("console", lambda m: m.type == "error" and self.problems.append(m.text))

    def close(self) -> None:
        self.context.close()


@pytest.fixture
def browsers(browser):
    opened = []

    def make(viewport=LANDSCAPE) -> Browser:
        opened.append(Browser(browser, viewport))
        return opened[-1]

    yield make
    for instance in opened:
        instance.close()


class Participant:
    """The participant screen with a pen (trusted pen events through the DevTools protocol)."""

    def __init__(self, page):
        self.page = page
        self.cdp = page.context.new_cdp_session(page)

    def eval(self, script: str, arg=None):
        return self.page.evaluate(script, arg)

    def wait(self, script: str, timeout: float = 15_000) -> None:
        self.page.wait_for_function(script, timeout=timeout)

    def start(self) -> None:
        self.wait("() => window.realpen && window.realpen.ready && "
                  "window.realpen.study.screen === 'start'")
        self.page.click("#start")

    def trial(self, n: int) -> dict:
        """Wait until trial ``n`` is on screen and ready; return the page's copy of it."""
        self.wait(f"() => realpen.study.screen === 'trial' && realpen.study.trial === {n} && "
                  f"realpen.study.t0 !== null && realpen.study.step !== 'sending'")
        return self.eval("realpen.study.next")

    def stroke(self, points, dt: float = 0.008) -> None:
        """A pen stroke through ``points`` (x, y relative to the writing surface, 0–1)."""
        box = self.page.locator("#ink").bounding_box()
        t0 = time.time()
        for i, (u, v) in enumerate(points):
            kind = "mousePressed" if i == 0 else "mouseMoved"
            self.pen(kind, box["x"] + u * box["width"], box["y"] + v * box["height"], 0.55,
                     t0 + i * dt)
        u, v = points[-1]
        self.pen("mouseReleased", box["x"] + u * box["width"], box["y"] + v * box["height"], 0.0,
                 t0 + len(points) * dt)

    def pen(self, kind: str, x: float, y: float, pressure: float, t: float) -> None:
        self.cdp.send("Input.dispatchMouseEvent", {
            "type": kind, "x": x, "y": y, "button": "left", "buttons": 0 if kind ==
            "mouseReleased" else 1, "clickCount": 1, "pointerType": "pen", "force": pressure,
            "tiltX": 10, "tiltY": -5, "timestamp": t})

    def settle(self) -> None:
        self.wait("() => !realpen.down && realpen.link.state === 'open' && "
                  "realpen.link.unacked === 0")


def line(u0, v0, u1, v1, n: int = 6):
    return [(u0 + (u1 - u0) * i / (n - 1), v0 + (v1 - v0) * i / (n - 1)) for i in range(n)]


def letter_b(u: float, v: float, size: float = 0.12):
    """A "B" in one stroke: up the stem, then both bowls down to its foot (u, v: the top left,
    in surface fractions)."""
    bowl = size * 0.35
    return [(u, v + size), (u, v), (u + bowl, v + size * 0.12), (u + bowl, v + size * 0.38),
            (u, v + size / 2), (u + bowl * 1.2, v + size * 0.62), (u + bowl * 1.2, v + size * 0.88),
            (u, v + size)]


def write_lines_and_two_bs(screen: Participant) -> int:
    """Study 1's task: some lines and the letter B twice. Returns the number of strokes."""
    strokes = [line(0.1, 0.2, 0.5, 0.2, 4), line(0.1, 0.35, 0.5, 0.35, 4),
               letter_b(0.6, 0.2), letter_b(0.8, 0.2)]
    for points in strokes:
        screen.stroke(points)
    return len(strokes)


def zigzag_and_circle():
    zigzag = [(0.1 + 0.05 * i, 0.3 + (0.08 if i % 2 else 0)) for i in range(8)]
    circle = [(0.7 + 0.1 * math.cos(2 * math.pi * i / 10), 0.4 + 0.15 * math.sin(2 * math.pi * i / 10))
              for i in range(11)]
    return [zigzag, circle]


def store_rows(server, sql: str, *args) -> list[tuple]:
    with sqlite3.connect(server.store) as db:
        return db.execute(sql, args).fetchall()


def api(server, method: str, path: str, body=None) -> httpx.Response:
    return server.client.request(method, server.base + path.lstrip("/"), json=body)


def participant_url(server, session: int) -> str:
    return f"{server.base}study/participant?session={session}&token={server.token}"


def open_console(context: Browser, url: str):
    page = context.context.new_page()
    page.goto(url)
    page.wait_for_function("() => window.realpenStudy && window.realpenStudy.ready")
    return page


def likert(page, question: str, value: int) -> None:
    page.click(f".question[data-id={question}] button[data-value='{value}']")


def expected_likert(n: int) -> tuple[int, int]:
    """Study 1's answers in the tests: a different pair for every trial."""
    return n % 5 + 1, (n * 2) % 5 + 1


# ---- 1. a whole study-1 session, from the operator console to the export ----------------------

def test_a_whole_study_1_session_from_the_console_to_the_export(server, browsers, tmp_path):
    operator_side = browsers(DESKTOP)
    console = open_console(operator_side, f"{server.base}study?token={server.token}")
    assert console.title() == "RealPen studies — operator"
    assert server.token not in console.url  # the cookie works: the token leaves the address
    designs = console.locator("#design option").evaluate_all("os => os.map(o => o.value)")
    assert designs[:2] == ["study1", "study2"]
    console.select_option("#design", "study1")
    # The design asks for demographics and consent: its fields and consent text are shown.
    assert console.locator("#demographic-fields [data-field]").evaluate_all(
        "fs => fs.map(f => f.dataset.field)") == ["age", "gender", "handedness"]
    assert "I agree to take part" in console.locator("#consent-text").inner_text()
    console.fill("#participant", "P01")
    console.fill("#site", "Lab A")
    console.fill("#demo-age", "31")
    console.fill("#demo-gender", "female")
    console.select_option("#demo-handedness", "right")
    console.click("#start")  # no consent yet: the server refuses, the console says why
    console.wait_for_function("() => document.getElementById('form-error').textContent !== ''")
    assert "consent" in console.locator("#form-error").inner_text()
    console.check("#consent")
    console.click("#start")
    console.wait_for_function("() => realpenStudy.progress && realpenStudy.progress.trials === 7")
    session = console.evaluate("realpenStudy.progress.session")
    assert console.locator("#cur-progress").inner_text() == "Trial 1 of 7 · 0 answered"
    assert console.locator("#cur-state").inner_text() == "Running"
    url = console.locator("#participant-url").inner_text()
    assert url == participant_url(server, session)  # with the token: typed on a tablet
    # Typing the same participant again resumes their session (200), it makes no second one.
    console.fill("#participant", "P01")
    console.click("#start")
    console.wait_for_function("() => /already has session/.test("
                              "document.getElementById('form-note').textContent)")
    assert len(api(server, "GET", "/api/sessions").json()["sessions"]) == 1

    # The console opens the participant screen in a new window...
    with operator_side.context.expect_page() as popup:
        console.click("#open-participant")
    popup.value.wait_for_function("() => window.realpen && window.realpen.ready")
    assert popup.value.url == url.split("&token=")[0]  # opened with the token, then forgot it
    popup.value.close()
    # ...and a tablet opens it at the URL the console shows (the participant's own device; it
    # has no cookie, so without the token it gets nothing).
    tablet = browsers(LANDSCAPE)
    page = tablet.context.new_page()
    assert page.goto(url.split("&token=")[0]).status == 401
    page.goto(url)
    screen = Participant(page)
    screen.start()
    assert server.token not in page.url
    strokes_per_trial, clock = {}, {}
    for n in range(1, 7):
        waited = time.monotonic()
        trial = screen.trial(n)
        shown = time.monotonic()
        # Only the task: no design, condition or modality names anywhere on the screen.
        text = page.locator("body").inner_text()
        assert trial["task"] in text and "Study 1" not in text and "tactile" not in text.lower()
        assert screen.eval("[realpen.pen, realpen.modality, realpen.ink, "
                           "realpen.audio.playing]") == ["ballpoint", "tactile", "hidden",
                                                         "ballpoint"]
        assert page.locator(".question").first.is_hidden()  # questions come after the writing
        strokes_per_trial[n] = write_lines_and_two_bs(screen)
        assert screen.eval("realpen.inkedPixels()") == 0  # hidden ink: nothing drawn
        page.click("#done")
        q1, q2 = expected_likert(n)
        likert(page, "Q1", q1)
        assert page.locator("#next").is_disabled()  # both questions are required
        likert(page, "Q2", q2)
        if n == 1:
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "study-participant.png"))
        clicked = time.monotonic()
        page.click("#next")
        # The response time runs from the trial on screen to the answer: it lies between what
        # the test saw from either side of those two moments.
        clock[n] = ((clicked - shown) * 1000, (time.monotonic() - waited) * 1000)
        if n == 3:
            # The operator pauses during trial 4: the participant sees only "Please wait" (the
            # trial starts again, with a new clock, when the session resumes).
            screen.trial(4)
            console.click("#pause")
            console.wait_for_function("() => realpenStudy.progress.state === 'paused'")
            assert console.locator("#pause").is_disabled()
            screen.wait("() => realpen.study.screen === 'wait'")
            assert page.locator("#screen-title").inner_text() == "Please wait"
            console.wait_for_function("() => realpenStudy.progress.answered === 3")
            console.screenshot(path=str(ARTIFACTS / "study-operator.png"), full_page=True)
            console.click("#resume")
    # The comments: a text question and no writing surface.
    trial = screen.trial(7)
    assert page.locator("#ink").is_hidden() and page.locator("textarea").is_visible()
    page.fill("textarea", "  B felt closest to a ballpoint.  ")
    page.click("#next")
    screen.wait("() => realpen.study.screen === 'done'")
    assert page.locator("#screen-title").inner_text() == "Thank you"
    screen.settle()
    assert screen.eval("realpen.link.errors") == 0  # every pen_down's session and trial taken
    console.wait_for_function("() => realpenStudy.progress.state === 'finished'")
    assert console.locator("#cur-state").inner_text() == "Finished"
    assert console.locator("#cur-progress").inner_text() == "Complete: all 7 trials answered"
    assert console.locator("#sessions tbody tr").first.inner_text().split("\t")[4] == "Finished"
    assert operator_side.problems == [UNPROCESSABLE]  # the refusal without consent
    # the URL without the token: only 401s (Chromium may log the page and a sub-request)
    assert tablet.problems and set(tablet.problems) == {REFUSED.format(401, "Unauthorized")}

    # What the server stored: through the API, the store and the export.
    progress = api(server, "GET", f"/api/sessions/{session}").json()
    assert (progress["state"], progress["answered"], progress["next"]) == ("finished", 7, None)
    rts = dict(store_rows(server, "SELECT n, rt_ms FROM trials WHERE session_id = ?", session))
    sent = {entry["trial"]: entry for entry in screen.eval("realpen.study.sent")}
    assert sorted(rts) == list(range(1, 8))
    for n, rt in rts.items():
        assert rt > 0 and rt == pytest.approx(sent[n]["rt_ms"])  # the page's own measure
        if n in clock:
            assert clock[n][0] < rt < clock[n][1]
    answers = store_rows(server, "SELECT n, question, answer FROM answers WHERE session_id = ? "
                                 "ORDER BY n, question", session)
    expected = [(n, q, str(v)) for n in range(1, 7) for q, v in zip(("Q1", "Q2"),
                                                                      expected_likert(n))]
    assert answers == expected + [(7, "comments", "B felt closest to a ballpoint.")]
    # Every stroke carries its trial; the writing page's pipeline stored them (pen, modality).
    strokes = store_rows(server, "SELECT trial, count(*), min(sample_count), pen, modality, ink, "
                                 "pointer_type FROM strokes WHERE study_session = ? GROUP BY trial, "
                                 "pen, modality, ink, pointer_type ORDER BY trial", session)
    assert [(row[0], row[1]) for row in strokes] == sorted(strokes_per_trial.items())
    assert all(row[2] >= 4 and row[3:] == ("ballpoint", "tactile", "hidden", "pen")
               for row in strokes)
    participant = store_rows(server, "SELECT code, site, age, gender, handedness, consent FROM "
                                     "participants")
    assert participant == [("P01", "Lab A", 31, "female", "right", 1)]

    from realpen.study.export import export_trials
    summary = export_trials(server.store, tmp_path / "trials.csv", design="study1",
                            strokes=tmp_path / "strokes.csv")
    with open(tmp_path / "trials.csv", newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert summary.rows == len(rows) == 13
    conditions = {n: c for n, c in store_rows(server, "SELECT n, condition FROM trials WHERE "
                                                      "session_id = ?", session)}
    for row in rows[:12]:
        n = int(row["trial"])
        assert row["condition"] == conditions[n] and row["modality"] == "tactile"
        assert row["answer"] == str(dict(zip(("Q1", "Q2"), expected_likert(n)))[row["question"]])
        assert float(row["rt_ms"]) == pytest.approx(rts[n], abs=1e-3)
    with open(tmp_path / "strokes.csv", newline="", encoding="utf-8") as handle:
        sampled = {(int(r["trial"]), int(r["stroke"])) for r in csv.DictReader(handle)}
    assert {trial for trial, _ in sampled} == set(range(1, 7))
    assert summary.strokes == sum(strokes_per_trial.values())


# ---- 2. a study-2 modality block and its questionnaire, on a tablet in portrait ---------------

def test_a_study_2_modality_block_and_its_questionnaire_on_a_tablet(server, browsers):
    created = api(server, "POST", "/api/sessions", {
        "design": "study2", "participant": "P02", "site": "Lab B", "consent": True,
        "demographics": {"age": 27, "gender": "male", "handedness": "left"}})
    assert created.status_code == 201
    session = created.json()["session"]
    tablet = browsers(PORTRAIT)
    page = tablet.context.new_page()
    page.goto(participant_url(server, session))
    screen = Participant(page)
    screen.start()
    block = None
    chosen = {}
    for n in range(1, 31):
        trial = screen.trial(n)  # the server's `next` (the participant is not told the pen)
        if n == 1:
            assert trial == api(server, "GET", f"/api/sessions/{session}/next").json()
        block = block or trial["block"]
        assert trial["block"] == block and trial["phase"] == ("training" if n <= 12
                                                              else "experimental")
        assert screen.eval("[realpen.pen, realpen.modality, realpen.ink]") == \
            [trial["pen"], trial["live_modality"], "hidden"]
        screen.stroke(line(0.15, 0.3, 0.75, 0.3, 5))  # the line (the test spares the B)
        assert page.locator("#done").is_enabled()
        page.click("#done")
        # Answer right, except on every third trial.
        pens = trial["questions"][0]["choices"]
        answer = trial["pen"] if n % 3 else pens[(pens.index(trial["pen"]) + 1) % len(pens)]
        chosen[n] = answer
        if n == 13:
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "study-participant-portrait.png"))
        page.click(f".question[data-id=pen] button[data-value={answer}]")  # the answer: no Next
        if n <= 12:  # a training trial then names the right pen, until the participant goes on
            screen.wait("() => window.realpen.study.screen === 'feedback'")
            assert page.locator("#screen-text").inner_text() == f"It was the {trial['pen']}."
            assert screen.eval("realpen.study.feedback") == {"correct": answer == trial["pen"],
                                                              "answer": trial["pen"]}
            page.click("#continue")
    screen.trial(31)  # the next modality block starts...
    # ...which this test answers through the API, while the screen shows trial 31.
    for n in range(31, 91):
        trial = api(server, "GET", f"/api/sessions/{session}/next").json()
        assert trial["trial"] == n
        reply = api(server, "POST", f"/api/sessions/{session}/trials/{n}",
                    {"answers": {"pen": trial["pen"]}, "rt_ms": 1500.0})
        assert reply.status_code == 201, reply.text
    # The screen's trial 31 is answered already: its answer gets a 409, and the screen goes on
    # with the server's next trial, the first block's questionnaire.
    screen.stroke(line(0.2, 0.3, 0.6, 0.3))
    page.click("#done")
    page.click(".question[data-id=pen] button[data-value=pencil]")
    trial = screen.trial(91)
    assert screen.eval("realpen.study.sent.at(-1)")["status"] == 409
    assert (trial["phase"], trial["condition"], trial["pen"]) == ("questionnaire", block,
                                                                  "ballpoint")
    assert screen.eval("[realpen.pen, realpen.ink]") == ["ballpoint", "visible"]
    for points in zigzag_and_circle():
        screen.stroke(points)
    assert screen.eval("realpen.inkedPixels()") > 100  # visible ink this time
    page.click("#done")
    questions = [q["id"] for q in trial["questions"]]
    assert questions[:3] == ["realism", "comfort", "strength"]
    for value, question in enumerate(questions, start=2):
        likert(page, question, value)
    anchors = page.locator(".question[data-id=strength] .anchor").all_inner_texts()
    assert anchors == ["too subtle", "just right", "too strong"]
    page.screenshot(path=str(ARTIFACTS / "study-participant-questionnaire.png"))
    page.click("#next")
    screen.trial(92)
    screen.settle()
    assert screen.eval("realpen.link.errors") == 0

    # The operator finishes the session from the console (with a confirmation); the screen,
    # in the middle of trial 92, thanks the participant.
    operator_side = browsers(DESKTOP)
    console = open_console(operator_side, f"{server.base}study?token={server.token}")
    console.click(f"#sessions tbody tr[data-session='{session}']")
    console.wait_for_function(f"() => realpenStudy.progress && "
                              f"realpenStudy.progress.session === {session}")
    assert console.locator("#cur-progress").inner_text() == "Trial 92 of 93 · 91 answered"
    console.click("#finish")
    assert console.locator("#finish-dialog").is_visible()
    console.click("#finish-dialog button[value=cancel]")
    assert console.evaluate("realpenStudy.progress.state") == "running"
    console.click("#finish")
    console.click("#finish-confirm")
    console.wait_for_function("() => realpenStudy.progress.state === 'finished'")
    assert console.locator("#cur-progress").inner_text() == "Finished: 91 of 93 trials answered"
    screen.wait("() => realpen.study.screen === 'done'", timeout=10_000)
    assert tablet.problems == [CONFLICT] and operator_side.problems == []  # trial 31's 409

    stored = store_rows(server, "SELECT t.n, t.pen, t.modality, a.answer, a.correct, t.rt_ms FROM "
                                "trials t JOIN answers a ON a.session_id = t.session_id AND "
                                "a.n = t.n WHERE t.session_id = ? AND t.n <= 30 ORDER BY t.n",
                        session)
    assert [row[0] for row in stored] == list(range(1, 31))
    for n, pen, modality, answer, correct, rt in stored:
        assert modality == block and answer == chosen[n] and correct == (answer == pen) and rt > 0
    assert sum(1 for row in stored if not row[4]) == 10
    strokes = store_rows(server, "SELECT s.trial, s.pen, s.modality, t.pen FROM strokes s JOIN "
                                 "trials t ON t.session_id = s.study_session AND t.n = s.trial "
                                 "WHERE s.study_session = ? ORDER BY s.id", session)
    by_trial = {}
    for trial_n, pen, modality, planned in strokes:
        by_trial[trial_n] = by_trial.get(trial_n, 0) + 1
        assert pen == planned and (modality == block or trial_n == 31)
    assert by_trial == {**{n: 1 for n in range(1, 31)}, 31: 1, 91: 2}
    questionnaire = store_rows(server, "SELECT question, answer FROM answers WHERE session_id = ? "
                                       "AND n = 91 ORDER BY question", session)
    assert dict(questionnaire) == {q: str(v) for v, q in enumerate(questions, start=2)}


# ---- 3. reloads, lost replies and a pending answer --------------------------------------------

def test_a_reload_and_lost_replies_resume_where_the_server_says(server, browsers):
    created = api(server, "POST", "/api/sessions", {"design": "study1", "participant": "P03",
                                                    "consent": True})
    session = created.json()["session"]
    tablet = browsers(LANDSCAPE)
    page = tablet.context.new_page()
    page.goto(participant_url(server, session))
    screen = Participant(page)
    screen.start()
    screen.trial(1)
    screen.stroke(line(0.1, 0.2, 0.5, 0.2))
    screen.settle()
    # A reload in the middle of trial 1: the screen asks to continue, then shows trial 1 again
    # (a new clock, a clean surface), and the stroke drawn before stays stored with trial 1.
    page.reload()
    screen.wait("() => window.realpen && window.realpen.ready")
    assert page.locator("#start").inner_text() == "Start"
    page.click("#start")
    screen.trial(1)
    screen.stroke(line(0.1, 0.4, 0.5, 0.4))
    page.click("#done")
    likert(page, "Q1", 2)
    likert(page, "Q2", 3)
    page.click("#next")
    screen.trial(2)

    # Trial 2's answer is stored, but its reply is lost (the network fails on the way back):
    # the screen says "Reconnecting…", sends again, gets 409 (stored before) and goes on.
    lost = {"replies": 0}

    def lose_the_reply(route):
        if lost["replies"] == 0:
            response = route.fetch()
            assert response.status == 201
            lost["replies"] += 1
            route.abort()
        else:
            route.continue_()

    page.route(f"**/api/sessions/{session}/trials/2", lose_the_reply)
    screen.stroke(line(0.1, 0.2, 0.5, 0.2))
    page.click("#done")
    likert(page, "Q1", 4)
    likert(page, "Q2", 5)
    page.click("#next")
    screen.trial(3)
    assert screen.eval("realpen.study.retries") >= 1
    assert screen.eval("realpen.study.sent.at(-1)") | {"rt_ms": 0} == {
        "trial": 2, "answers": {"Q1": 4, "Q2": 5}, "rt_ms": 0, "status": 409}
    page.unroute(f"**/api/sessions/{session}/trials/2")

    # Trial 3's answer cannot get through at all (the server is away): "Reconnecting…" stays,
    # the answer waits in sessionStorage, and a reload sends it, once the server is back.
    page.route(f"**/api/sessions/{session}/trials/3", lambda route: route.abort())
    screen.stroke(line(0.1, 0.2, 0.5, 0.2))
    page.click("#done")
    likert(page, "Q1", 1)
    likert(page, "Q2", 1)
    page.click("#next")
    screen.wait("() => realpen.study.reconnecting")
    assert page.locator("#reconnecting").is_visible()
    assert page.locator("#reconnecting").inner_text().strip() == "Reconnecting…"
    pending = json.loads(screen.eval(f"sessionStorage.getItem('realpen.study.pending.{session}')"))
    assert pending["trial"] == 3 and pending["answers"] == {"Q1": 1, "Q2": 1}
    screen.settle()
    page.unroute(f"**/api/sessions/{session}/trials/3")
    page.reload()
    screen.wait("() => window.realpen && window.realpen.ready")
    assert page.locator("#start").inner_text() == "Continue"
    page.click("#start")
    screen.trial(4)
    assert screen.eval(f"sessionStorage.getItem('realpen.study.pending.{session}')") is None
    assert screen.eval("realpen.link.errors") == 0
    rts = dict(store_rows(server, "SELECT n, rt_ms FROM trials WHERE session_id = ? AND "
                                  "rt_ms IS NOT NULL", session))
    assert sorted(rts) == [1, 2, 3] and rts[3] == pytest.approx(pending["rt_ms"])
    assert store_rows(server, "SELECT n, count(*) FROM answers WHERE session_id = ? GROUP BY n",
                      session) == [(1, 2), (2, 2), (3, 2)]  # each answer stored once
    assert dict(store_rows(server, "SELECT trial, count(*) FROM strokes WHERE study_session = ? "
                                   "GROUP BY trial", session)) == {1: 2, 2: 1, 3: 1}
    assert set(tablet.problems) <= {NETWORK_FAILURE, CONFLICT}  # only what the test made


# ---- 4. the server (LAN mode) killed and started again while the participant answers --------

def test_the_participant_screen_goes_on_across_a_server_restart(browser, browsers, tmp_path):
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = str(probe.getsockname()[1])
    tablet = browsers()
    lan = ("--lan", "--host", "127.0.0.1", "--port", port)  # a tablet's server: with its token
    with serve(tmp_path, *lan) as first:
        first.store = tmp_path / "strokes.sqlite3"
        bearer = {"Authorization": f"Bearer {first.token}"}
        with httpx.Client(timeout=10, headers=bearer) as client:
            first.client = client
            session = api(first, "POST", "/api/sessions", {"design": "study1", "participant": "P09",
                                                           "consent": True}).json()["session"]
        page = tablet.context.new_page()
        page.goto(participant_url(first, session))
        screen = Participant(page)
        screen.start()
        for n in (1, 2):
            screen.trial(n)
            screen.stroke(line(0.1, 0.3, 0.6, 0.3, 5))
            screen.settle()
            page.click("#done")
            likert(page, "Q1", n + 1)
            likert(page, "Q2", n + 2)
            if n == 2:  # the server dies with the answer about to be sent
                first.process.kill()
                first.process.wait(timeout=10)
            page.click("#next")
        screen.wait("() => realpen.study.reconnecting === true")
        assert page.locator("#reconnecting").is_visible()
        with serve(tmp_path, *lan) as second:  # same port, same store, same data folder
            second.store = first.store
            assert second.token == first.token  # the LAN token is kept: the tablet carries on
            screen.trial(3)  # the answer got through to the new server; the session goes on
            assert not page.locator("#reconnecting").is_visible()
            with httpx.Client(timeout=10, headers=bearer) as client:
                second.client = client
                progress = api(second, "GET", f"/api/sessions/{session}").json()
    assert (progress["answered"], progress["next"]) == (2, 3)
    stored = store_rows(first, "SELECT n, question, answer FROM answers ORDER BY n, question")
    assert stored == [(1, "Q1", "2"), (1, "Q2", "3"), (2, "Q1", "3"), (2, "Q2", "4")]
    strokes = store_rows(first, "SELECT trial, COUNT(*) FROM strokes WHERE study_session = ? "
                                "GROUP BY trial ORDER BY trial", session)
    assert strokes == [(1, 1), (2, 1)]
    # only the refused connections while no server listened
    assert all("net::ERR_CONNECTION_REFUSED" in problem for problem in tablet.problems), \
        tablet.problems
