"""Numbers and names the live page's JavaScript shares with the Python package.

The page is plain ES modules served as they are (no build step), so what it must agree on with
the host and the firmware is written twice: the pen protocol (``static/pen-protocol.js`` and
:mod:`realpen.device.protocol`), the upload windows and baud rate of the transports
(``static/pen-transport-*.js`` and :mod:`realpen.device.transport`), the speed window
(``static/pen.js`` and :mod:`realpen.sound.stroke`), the live messages' modalities and limits
(``static/app.js``, ``static/writer.js``, ``static/study/participant.js`` and
:mod:`realpen.live.messages`). These tests read the JavaScript as text and compare each value
with the Python one, imported where it lives: a value changed on one side only, or a name moved
away on the Python side, fails here.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from realpen.device import protocol, transport

STATIC = Path(__file__).resolve().parents[1] / "src" / "realpen" / "live" / "static"
CONST = re.compile(r"^(?:export\s+)?const\s+([A-Z][A-Z0-9_]*)\s*=\s*(.+?);", re.M)
TABLE = re.compile(r"^(?:export\s+)?const\s+([A-Z][A-Z0-9_]*)\s*=\s*\{(.*?)\};", re.M | re.S)
TABLE_ENTRY = re.compile(r"\[([A-Z][A-Z0-9_]*)\]\s*:\s*('(?:[^'\\]|\\.)*'|\"(?:[^\"\\]|\\.)*\")")


def js_constants(text: str) -> dict[str, object]:
    """The module-level ``const NAME = literal;`` of a JS module (numbers, strings, arrays of
    them), by name; an expression that is not a literal is left out."""
    found: dict[str, object] = {}
    for name, value in CONST.findall(text):
        try:
            found[name] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            continue
    return found


def js_table(text: str, name: str) -> dict[object, str]:
    """``const NAME = { [KEY]: 'text', … };`` with each KEY read from the module's constants."""
    constants = js_constants(text)
    body = next((b for n, b in TABLE.findall(text) if n == name), None)
    assert body is not None, f"no table {name} in the module"
    return {constants[key]: ast.literal_eval(value) for key, value in TABLE_ENTRY.findall(body)}


def differences(js: dict[str, object], python: dict[str, object]) -> list[str]:
    """One line per name whose value differs, or that one side lacks."""
    lines = []
    for name in sorted(set(js) | set(python)):
        if name not in js:
            lines.append(f"{name}: only in Python ({python[name]!r})")
        elif name not in python:
            lines.append(f"{name}: only in JavaScript ({js[name]!r})")
        elif js[name] != python[name] or type(js[name]) is not type(python[name]):
            lines.append(f"{name}: JavaScript {js[name]!r}, Python {python[name]!r}")
    return lines


def read(name: str) -> str:
    return (STATIC / name).read_text(encoding="utf-8")


def python_protocol_constants() -> dict[str, object]:
    """protocol.py's public constants (numbers and UUID strings), as the firmware has them."""
    return {name: value for name, value in vars(protocol).items()
            if re.fullmatch(r"[A-Z][A-Z0-9_]*", name) and type(value) in (int, str)}


# ---- the pen protocol -------------------------------------------------------------------------

def test_the_page_codec_has_every_protocol_constant_with_the_same_value():
    """Versions, limits, frame types, NACK codes, event kinds, features, SET_STATE scales and
    the Bluetooth UUIDs: the same names with the same values on both sides, none missing."""
    js = {name: value for name, value in js_constants(read("pen-protocol.js")).items()
          if type(value) in (int, str)}
    assert differences(js, python_protocol_constants()) == []


@pytest.mark.parametrize("table", ["NACK_TEXT", "TYPE_NAMES", "EVENT_NAMES"])
def test_the_page_codec_names_codes_types_and_events_as_protocol_py(table):
    assert js_table(read("pen-protocol.js"), table) == getattr(protocol, table)


# ---- the transports ---------------------------------------------------------------------------

def test_upload_windows_and_baud_rate_match_the_python_transports():
    """How far an upload runs ahead of the pen (USB, Bluetooth), the serial line's rate, and
    the smallest Bluetooth write (the minimum ATT MTU of 23, less 3)."""
    serial = js_constants(read("pen-transport-serial.js"))
    ble = js_constants(read("pen-transport-ble.js"))
    js = {"UPLOAD_WINDOW": serial.get("UPLOAD_WINDOW"), "BAUD_RATE": serial.get("BAUD_RATE"),
          "BLE_UPLOAD_WINDOW": ble.get("BLE_UPLOAD_WINDOW"),
          "DEFAULT_BLE_WRITE": ble.get("BLE_PIECES", [None])[-1]}
    python = {"UPLOAD_WINDOW": transport.UPLOAD_WINDOW, "BAUD_RATE": transport.BAUD_RATE,
              "BLE_UPLOAD_WINDOW": transport.BLE_UPLOAD_WINDOW,
              "DEFAULT_BLE_WRITE": transport.DEFAULT_BLE_WRITE}
    assert differences(js, python) == []


def test_each_transport_uploads_with_its_own_window():
    """The link asks the transport (``uploadWindow``), as the Python client asks
    ``Transport.upload_window``: each transport module hands out its own constant."""
    assert "this.uploadWindow = UPLOAD_WINDOW;" in read("pen-transport-serial.js")
    assert "this.uploadWindow = BLE_UPLOAD_WINDOW;" in read("pen-transport-ble.js")
    assert "transport.uploadWindow" in read("pen-link.js")
    assert "UPLOAD_WINDOW =" not in read("pen-link.js")  # one definition per side


# ---- the page's pen samples and live messages -----------------------------------------------

def test_the_speed_window_matches_the_stroke_renderer():
    from realpen.sound import stroke

    assert js_constants(read("pen.js"))["SPEED_WINDOW_MS"] == stroke.SPEED_WINDOW_MS


def test_the_page_modalities_are_the_live_messages_modalities():
    """One list on the page (writer.js, which the writing page and the participant screen
    import), the server's, and the old names both read as today's."""
    from realpen import defaults
    from realpen.live import messages

    text = read("writer.js")
    assert tuple(js_constants(text)["MODALITIES"]) == messages.MODALITIES == defaults.MODALITIES
    old = re.search(r"^export const OLD_MODALITY_NAMES = (\{.*?\});", text, re.M | re.S)
    assert old is not None and ast.literal_eval(old.group(1)) == defaults.OLD_MODALITY_NAMES
    for module in ("app.js", "study/participant.js"):  # no copy of their own
        assert "MODALITIES = [" not in read(module) and "'auditory-tactile'" not in read(module)


def test_the_writer_batch_fallbacks_are_the_server_limits():
    """Before the server's config arrives the writer batches by the server's own defaults."""
    from realpen.live import messages

    text = read("writer.js")
    samples = re.search(r"config\.max_samples \|\| (\d+)", text)
    size = re.search(r"config\.max_message_bytes \|\| (\d+)", text)
    assert samples and size, "writer.js no longer batches by config.max_samples/max_message_bytes"
    assert int(samples[1]) == messages.MAX_SAMPLES
    assert int(size[1]) == messages.MAX_MESSAGE_BYTES


# ---- the checks themselves ----------------------------------------------------------------

def test_a_value_changed_on_one_side_only_is_found():
    """The reading and the comparison catch a drift (here UPLOAD_WINDOW 16 → 17 and a NACK
    text edited in the JavaScript), a constant missing on one side, and a string for a number."""
    serial = read("pen-transport-serial.js").replace("UPLOAD_WINDOW = 16;", "UPLOAD_WINDOW = 17;")
    assert differences({"UPLOAD_WINDOW": js_constants(serial)["UPLOAD_WINDOW"]},
                       {"UPLOAD_WINDOW": transport.UPLOAD_WINDOW}) == [
        "UPLOAD_WINDOW: JavaScript 17, Python 16"]
    codec = read("pen-protocol.js")
    assert js_table(codec.replace("'pattern CRC-32 mismatch'", "'CRC mismatch'"),
                    "NACK_TEXT") != protocol.NACK_TEXT
    without = codec.replace("export const E_BAD_STATE = 11;\n", "")
    assert differences(js_constants(without), python_protocol_constants()) == [
        "E_BAD_STATE: only in Python (11)"]
    assert differences({"MAX_CHUNK": "180"}, {"MAX_CHUNK": 180}) == [
        "MAX_CHUNK: JavaScript '180', Python 180"]
