"""Eq. 1 coupling: the gain, its clamp and smoother, the JSON, and the least-squares fit."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from realpen.errors import ParameterError, RealPenError
from realpen.motion.coupling import Coupling, fit_coupling, load_measurements, one_pole

TRUTH = dict(c_p=0.8, c_op=0.15, c_x=0.015, c_ov=10.0)


def eq1(P, v, c_p, c_op, c_x, c_ov):
    return c_p * (P - c_op) + c_x * (v - c_ov)


def measurements(n=1000, noise=0.02, seed=0, pressure_range=(0.25, 1.0),
                 speed_range=(15.0, 150.0), a_max=None):
    """Noisy amplitudes from TRUTH; the default ranges keep Eq. 1 well inside (0, 3)."""
    rng = np.random.default_rng(seed)
    pressure = rng.uniform(*pressure_range, n)
    speed = rng.uniform(*speed_range, n)
    raw = eq1(pressure, speed, **TRUTH) + rng.normal(0.0, noise, n)
    return pressure, speed, raw if a_max is None else np.clip(raw, 0.0, a_max)


CLAMPED = dict(pressure_range=(0.02, 0.6), speed_range=(0.0, 60.0), a_max=0.8)


def test_gain_follows_eq1_exactly_inside_the_clamp():
    coupling = Coupling(**TRUTH, a_max=5.0)
    rng = np.random.default_rng(1)
    P, v = rng.uniform(0.01, 1, 500), rng.uniform(0, 200, 500)
    expected = eq1(P, v, **TRUTH)
    inside = (expected > 0) & (expected < 5.0)
    assert inside.sum() > 300
    np.testing.assert_allclose(coupling.gain_raw(P, v)[inside], expected[inside], rtol=1e-12)


def test_gain_is_clamped_and_zero_when_lifted():
    coupling = Coupling(**TRUTH, a_max=1.5)
    assert coupling.gain_raw(1.0, 1000.0) == 1.5
    assert coupling.gain_raw(0.05, 0.0) == 0.0           # Eq. 1 is negative here
    assert eq1(0.05, 0.0, **TRUTH) < 0
    assert coupling.gain_raw(0.0, 100.0) == 0.0          # lifted, however fast
    assert eq1(0.0, 100.0, **TRUTH) > 0
    gains = coupling.gain_raw(np.linspace(0, 1, 50), np.linspace(0, 300, 50))
    assert gains.min() >= 0 and gains.max() <= 1.5


def test_defaults_give_a_natural_level_for_ordinary_handwriting():
    coupling = Coupling()
    assert coupling.gain_raw(0.5, 50.0) == pytest.approx(1.0)    # ordinary writing: gain 1
    assert coupling.gain_raw(0.5, 0.0) == pytest.approx(0.0)     # pressed, not moving: silent
    assert coupling.gain_raw(0.8, 120.0) == coupling.a_max       # fast and hard: the clamp
    speeds = np.linspace(15, 80, 20)
    assert np.all(np.diff(coupling.gain_raw(0.5, speeds)) > 0)
    assert np.all(np.diff(coupling.gain_raw(np.linspace(0.3, 0.9, 20), 40.0)) > 0)


def test_one_pole_is_the_documented_recursion():
    rate, tau_ms = 48000, 5.0
    alpha = 1 - math.exp(-1 / (rate * tau_ms / 1000))
    rng = np.random.default_rng(2)
    target = rng.uniform(0, 2, 2000)
    expected, state = np.empty_like(target), 0.3
    for n, value in enumerate(target):
        state = state + alpha * (value - state)
        expected[n] = state
    np.testing.assert_allclose(one_pole(target, rate, tau_ms, initial=0.3), expected, rtol=1e-10)


def test_smoother_reaches_63_percent_after_one_time_constant_and_does_not_click():
    coupling = Coupling(smoothing_ms=5.0)
    rate = 48000
    step = np.ones(rate // 10)
    smoothed = coupling.smooth(step, rate)
    tau = int(rate * 0.005)
    assert smoothed[tau - 1] == pytest.approx(1 - math.exp(-1), abs=1e-3)
    assert np.max(np.diff(np.concatenate([[0.0], smoothed]))) < 0.005  # no sample-sized jump
    np.testing.assert_array_equal(Coupling(smoothing_ms=0).smooth(step, rate), step)


def test_playback_rate_is_bounded_and_rises_with_speed():
    coupling = Coupling()
    assert coupling.playback_rate(coupling.rate_speed_ref) == pytest.approx(1.0)
    speeds = np.linspace(0, 1000, 200)
    rates = coupling.playback_rate(speeds)
    assert rates.min() == coupling.rate_min and rates.max() == coupling.rate_max
    assert np.all(np.diff(rates) >= 0)
    assert coupling.playback_rate(100.0) == pytest.approx(2 ** 0.25)
    np.testing.assert_array_equal(Coupling(rate_exponent=0).playback_rate(speeds), 1.0)


def test_json_round_trip(tmp_path):
    coupling = Coupling(c_p=0.7, c_op=0.2, c_x=0.03, c_ov=5.0, a_max=1.8, smoothing_ms=3.0)
    document = coupling.to_json()
    assert document["format"] == "realpen.coupling/1"
    assert Coupling.from_json(json.loads(json.dumps(document))) == coupling
    path = tmp_path / "coupling.json"
    coupling.save(path)
    assert Coupling.load(path) == coupling
    assert [p.name for p in tmp_path.iterdir()] == ["coupling.json"]


@pytest.mark.parametrize("content,problem", [
    ("", "file is empty"),
    ("{not json", "not valid JSON"),
    ('{"c_p": "loud"}', "c_p"),
    ('{"c_p": NaN}', "NaN is not a number"),  # refused by the bounded JSON reader
    ('{"c_p": 1e999}', "c_p"),  # infinite: refused by the schema, which names the field
    ('{"a_max": 0}', "a_max"),
    ('{"c_p": 1, "gain": 2}', "gain"),
    ('{"format": "realpen.coupling/9"}', "format"),
    ("[1, 2]", "document"),
])
def test_bad_coupling_json_is_one_line_naming_the_file(tmp_path, content, problem):
    path = tmp_path / "coupling.json"
    path.write_text(content)
    with pytest.raises(RealPenError) as caught:
        Coupling.load(path)
    message = str(caught.value)
    assert message.startswith(str(path)) and problem in message and "\n" not in message


def relative_errors(coupling: Coupling, truth=TRUTH) -> dict[str, float]:
    return {name: abs(getattr(coupling, name) - value) / abs(value)
            for name, value in truth.items()}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_recovers_known_constants_within_5_percent(seed):
    pressure, speed, amplitude = measurements(seed=seed)
    assert amplitude.min() > 0
    fit = fit_coupling(pressure, speed, amplitude, fix="c_ov", value=TRUTH["c_ov"],
                       base=Coupling(a_max=10.0))
    errors = relative_errors(fit.coupling)
    assert max(errors.values()) < 0.05, errors
    assert fit.fixed == ("c_ov", TRUTH["c_ov"])
    assert fit.rmse == pytest.approx(0.02, rel=0.15)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_handles_clamped_measurements(seed):
    pressure, speed, amplitude = measurements(seed=seed, **CLAMPED)
    a_max = CLAMPED["a_max"]
    assert np.mean(amplitude == 0) > 0.05 and np.mean(amplitude == a_max) > 0.05
    fit = fit_coupling(pressure, speed, amplitude, value=TRUTH["c_ov"], base=Coupling(a_max=a_max))
    errors = relative_errors(fit.coupling)
    assert max(errors.values()) < 0.05, errors
    assert fit.clamped == int(np.sum((amplitude <= 0) | (amplitude >= a_max)))
    # a plain linear fit through the clamped rows is biased: the clamp has to be in the model
    design = np.column_stack([pressure, speed, np.ones_like(pressure)])
    naive, *_ = np.linalg.lstsq(design, amplitude, rcond=None)
    assert abs(naive[0] - TRUTH["c_p"]) / TRUTH["c_p"] > 0.05


def test_only_the_offset_is_identifiable_and_either_threshold_can_be_held():
    pressure, speed, amplitude = measurements(seed=4, **CLAMPED)
    base = Coupling(a_max=CLAMPED["a_max"])
    hold_speed = fit_coupling(pressure, speed, amplitude, "c_ov", TRUTH["c_ov"], base)
    hold_pressure = fit_coupling(pressure, speed, amplitude, "c_op", TRUTH["c_op"], base)
    assert abs(hold_pressure.coupling.c_ov - TRUTH["c_ov"]) / TRUTH["c_ov"] < 0.05
    assert abs(hold_speed.coupling.c_op - TRUTH["c_op"]) / TRUTH["c_op"] < 0.05
    offset = TRUTH["c_p"] * TRUTH["c_op"] + TRUTH["c_x"] * TRUTH["c_ov"]
    assert hold_speed.offset == pytest.approx(offset, rel=0.05)
    # a wrong held value moves the other threshold but not a single gain: the data cannot tell
    wrong = fit_coupling(pressure, speed, amplitude, "c_ov", 0.0, base)
    assert abs(wrong.coupling.c_op - TRUTH["c_op"]) > 0.1
    grid_p, grid_v = np.meshgrid(np.linspace(0.01, 1, 30), np.linspace(0, 200, 30))
    for other in (hold_pressure, wrong):
        np.testing.assert_allclose(other.coupling.gain_raw(grid_p, grid_v),
                                   hold_speed.coupling.gain_raw(grid_p, grid_v), atol=1e-9)
    assert fit_coupling(pressure, speed, amplitude, base=base).fixed == ("c_ov", base.c_ov)


def test_fit_ignores_lifted_rows_and_keeps_the_base_settings():
    pressure, speed, amplitude = measurements(seed=5)
    lifted = np.zeros(200), np.full(200, 80.0), np.full(200, 3.0)  # nonsense while lifted
    base = Coupling(a_max=10.0, smoothing_ms=8.0, rate_exponent=0.0)
    both = fit_coupling(np.concatenate([pressure, lifted[0]]), np.concatenate([speed, lifted[1]]),
                        np.concatenate([amplitude, lifted[2]]), value=TRUTH["c_ov"], base=base)
    assert both.rows == len(pressure)
    assert max(relative_errors(both.coupling).values()) < 0.05
    assert both.coupling.smoothing_ms == 8.0 and both.coupling.rate_exponent == 0.0


def test_fit_refuses_data_that_cannot_identify_the_constants():
    rng = np.random.default_rng(6)
    speed = rng.uniform(0, 100, 50)
    with pytest.raises(RealPenError, match="m.csv: pressure and speed must both vary"):
        fit_coupling(np.full(50, 0.5), speed, 0.01 * speed, source="m.csv")
    with pytest.raises(RealPenError, match="lockstep"):
        fit_coupling(speed / 100, speed, 0.01 * speed)
    with pytest.raises(RealPenError, match="at least 4 pen-down rows"):
        fit_coupling([0.5, 0.6, 0.0], [10, 20, 30], [0.1, 0.2, 0.3])
    with pytest.raises(ParameterError, match="^fix: choose c_ov or c_op") as caught:
        fit_coupling(*measurements(n=20), fix="c_x")
    assert caught.value.parameter == "fix"


def test_load_measurements(tmp_path):
    good = tmp_path / "m.csv"
    good.write_text("speed,pressure,amplitude,note\n10,0.5,0.4,1\n20,0.6,0.7,2\n")
    pressure, speed, amplitude = load_measurements(good)
    np.testing.assert_array_equal(pressure, [0.5, 0.6])
    np.testing.assert_array_equal(speed, [10, 20])
    np.testing.assert_array_equal(amplitude, [0.4, 0.7])
    cases = {"pressure,speed\n0.5,10\n": "missing amplitude",
             "pressure,speed,amplitude\n1.5,10,0.3\n": "pressure 1.5 must be between 0 and 1",
             "pressure,speed,amplitude\n0.5,-3,0.3\n": "speed -3 must be at least 0",
             "pressure,speed,amplitude\n0.5,10,inf\n": "NaN or infinite",
             "pressure,speed,amplitude\n0.5,10\n": "2 values for the 3 columns"}
    for content, problem in cases.items():
        bad = tmp_path / "bad.csv"
        bad.write_text(content)
        with pytest.raises(RealPenError, match=problem) as caught:
            load_measurements(bad)
        assert str(caught.value).startswith(str(bad))


@pytest.mark.parametrize("fix", ["c_ov", "c_op"])
@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_fit_refuses_a_held_value_that_is_not_finite(fix, value):
    pressure, speed, amplitude = measurements(seed=7)
    with pytest.raises(ParameterError, match="^value: must be a finite number"):
        fit_coupling(pressure, speed, amplitude, fix, value, source="m.csv")


@pytest.mark.parametrize("fix", ["c_ov", "c_op"])
@pytest.mark.parametrize("value", [1e308, -1e308, 1e200, 1e12])
def test_fit_refuses_constants_that_cannot_reproduce_the_fit(fix, value):
    # Held far from the data, the other threshold becomes huge (or infinite) and the two terms
    # of Eq. 1 cancel in floating point: the saved constants would not give the fitted gains.
    pressure, speed, amplitude = measurements(seed=7)
    with pytest.raises(RealPenError) as caught:
        fit_coupling(pressure, speed, amplitude, fix, value, base=Coupling(a_max=10.0),
                     source="m.csv")
    message = str(caught.value)
    assert message.startswith("m.csv: ") and "\n" not in message and "--" not in message
    assert fix in message and f"{value:g}" in message


def test_fit_keeps_a_distant_but_representable_held_value():
    pressure, speed, amplitude = measurements(seed=7)
    base = Coupling(a_max=10.0)
    near = fit_coupling(pressure, speed, amplitude, "c_ov", TRUTH["c_ov"], base)
    far = fit_coupling(pressure, speed, amplitude, "c_ov", 1000.0, base)
    assert math.isfinite(far.coupling.c_op) and far.coupling.c_ov == 1000.0
    grid_p, grid_v = np.meshgrid(np.linspace(0.01, 1, 20), np.linspace(0, 200, 20))
    np.testing.assert_allclose(far.coupling.gain_raw(grid_p, grid_v),
                               near.coupling.gain_raw(grid_p, grid_v), atol=1e-9)


def test_measurement_errors_name_the_file_line(tmp_path):
    cases = {"pressure,speed,amplitude\n\n0.5,10,0.3\n\n0.5,-3,0.3\n": "line 5: speed -3",
             "\n\npressure,speed,amplitude\n0.5,10,0.3\n1.5,10,0.3\n": "line 5: pressure 1.5",
             "pressure,speed,amplitude\n0.5,10,0.3\n\n0.5,10,loud\n": "line 4: 'loud'"}
    for content, problem in cases.items():
        path = tmp_path / "m.csv"
        path.write_text(content)
        with pytest.raises(RealPenError, match=problem) as caught:
            load_measurements(path)
        assert "data row" not in str(caught.value)


def test_coupling_and_fit_have_one_line_reprs():
    fit = fit_coupling(*measurements(seed=8))
    for item in (Coupling(), fit.coupling):
        text = repr(item)
        assert text.startswith("Coupling(c_p=") and "\n" not in text and len(text) < 200, text
        assert "mm/s" in text
    assert "c_ov=12 mm/s" in repr(Coupling())


def test_measurements_with_semicolons_and_decimal_commas(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("pressure;speed;amplitude\n0,5;10;0,4\n0,6;20,5;0,7\n")
    pressure, speed, amplitude = load_measurements(path)
    np.testing.assert_array_equal(pressure, [0.5, 0.6])
    np.testing.assert_array_equal(speed, [10, 20.5])
