"""Actuator responses, specs, measured CSVs and the capped weighting."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from realpen.errors import ParameterError, RealPenError
from realpen.tactile.actuator import Actuator, as_actuator, load_measured, parse_actuator, weighting


def test_lra_model_is_a_second_order_bandpass():
    act = parse_actuator("lra:f0=175,q=8")
    f = np.geomspace(20, 1000, 200)
    w0 = 2 * np.pi * 175
    # Analog band-pass (s/(Q w0)) / (s²/w0² + s/(Q w0) + 1): an independent definition.
    _, h = signal.freqs([1 / (8 * w0), 0], [1 / w0 ** 2, 1 / (8 * w0), 1], worN=2 * np.pi * f)
    assert np.allclose(act.response(f), np.abs(h), rtol=1e-9)
    assert act.response(175.0) == pytest.approx(1.0)


def test_piezo_and_flat():
    piezo = parse_actuator("piezo:f0=300,q=2")
    assert piezo.response(30.0) < 0.02 and piezo.response(3000.0) == pytest.approx(1, rel=0.02)
    assert parse_actuator("flat").response(np.array([10.0, 500.0])).tolist() == [1.0, 1.0]


@pytest.mark.parametrize("spec, message", [
    ("lra:f0=abc", "not a number"),
    ("lra:w=3", "not a parameter"),
    ("lra:q=-1", "must be a positive"),
    ("lra:f0=inf", "must be a positive finite"),
    ("voicecoil", "unknown actuator"),
])
def test_bad_specs(spec, message):
    with pytest.raises(ParameterError, match=message) as info:
        parse_actuator(spec)
    assert info.value.parameter == "actuator" and "--" not in str(info.value)


def test_measured_csv_linear_and_db(tmp_path):
    linear = tmp_path / "linear.csv"
    linear.write_text("frequency_hz,response\n50,0.1\n100,0.5\n200,1.0\n400,0.25\n")
    act = parse_actuator(str(linear))
    assert act.kind == "measured"
    assert act.response(200.0) == pytest.approx(1.0)
    assert act.response(1000.0) == pytest.approx(0.25)  # held beyond the table
    in_db = tmp_path / "db.csv"
    in_db.write_text("hz,gain_dB\n50,-20\n200,0\n")
    assert load_measured(in_db).response(50.0) == pytest.approx(0.1)


@pytest.mark.parametrize("content, message", [
    ("", "file is empty"),
    ("hz,response\n100,1\n", "at least two rows"),
    ("hz,response\n100,1\n90,1\n", "not strictly increasing"),
    ("hz,response\n100,1\n200,abc\n", "two numbers"),
    ("hz,response\n100,1\n200,-1\n", "must be positive"),
    ("hz,response\n100,1\n200\n", "two numbers"),
])
def test_malformed_measured_csv(tmp_path, content, message):
    path = tmp_path / "actuator.csv"
    path.write_text(content)
    with pytest.raises(RealPenError) as info:
        parse_actuator(str(path))
    assert str(path) in str(info.value) and message in str(info.value)


def test_weighting_equalises_and_caps():
    act = parse_actuator("lra:f0=175,q=8")
    freqs = np.array([175.0, 160.0, 190.0, 60.0, np.nan])
    result = weighting(act, freqs, (30.0, 672.0), cap_db=20)
    assert result.weights[0] == pytest.approx(1.0)
    unclipped = ~result.clipped & np.isfinite(freqs)
    product = result.weights[unclipped] * act.response(freqs[unclipped])
    assert np.allclose(product, 1.0)  # equal output strength where the cap is not active
    assert result.clipped.tolist() == [False, False, False, True, False]
    assert result.weights[3] == pytest.approx(10.0)
    assert np.isnan(result.weights[4])


def test_json_round_trip_model_and_measured(tmp_path):
    for spec in ("lra:f0=175,q=8", "piezo:f0=300,q=2", "flat"):
        act = parse_actuator(spec)
        data = act.to_json()
        assert data == {"spec": act.spec, "kind": act.kind, "params": act.params}
        assert Actuator.from_json(data) == act
    csv = tmp_path / "measured.csv"
    csv.write_text("frequency_hz,response\n50,0.1\n100,0.5\n200,1.0\n400,0.25\n")
    measured = parse_actuator(str(csv))
    data = measured.to_json()
    assert data["table_hz"] == [50.0, 100.0, 200.0, 400.0] and len(data["params"]["sha256"]) == 64
    again = Actuator.from_json(data)
    assert again == measured and hash(again) == hash(measured)
    assert again.response(150.0) == pytest.approx(measured.response(150.0))
    # The format-1 profile section (model actuators with null tables) reads the same.
    old = {"spec": "lra:f0=175,q=8", "kind": "lra", "params": {"f0": 175.0, "q": 8.0},
           "table_hz": None, "table_response": None}
    assert Actuator.from_json(old) == parse_actuator("lra:f0=175,q=8")


@pytest.mark.parametrize("data", [
    {"spec": "x", "kind": "voicecoil"},
    {"spec": "lra", "kind": "lra", "params": {"f0": -1, "q": 8}},
    {"spec": "lra", "kind": "lra", "params": {"f0": 175}},
    {"spec": "m.csv", "kind": "measured", "table_hz": [100, 50], "table_response": [1, 1]},
    {"spec": "flat", "kind": "flat", "colour": "red"},
    "lra:f0=175,q=8",
])
def test_from_json_refuses_malformed_documents(data):
    with pytest.raises(ParameterError) as info:
        Actuator.from_json(data)
    assert info.value.parameter == "actuator"


def test_repr_as_actuator_and_cap(tmp_path):
    assert repr(parse_actuator("lra")) == "Actuator('lra:f0=175,q=8')"
    csv = tmp_path / "a.csv"
    csv.write_text("hz,response\n50,0.1\n400,1\n")
    text = repr(parse_actuator(str(csv)))
    assert text == "Actuator(measured 'a.csv', 2 points, 50–400 Hz)" and len(text) < 200
    assert as_actuator("flat") == parse_actuator("flat")
    with pytest.raises(ParameterError, match="^actuator:"):
        as_actuator(175)
    with pytest.raises(ParameterError, match="^cap_db:"):
        weighting("flat", np.array([100.0]), (30.0, 600.0), cap_db=-1)
