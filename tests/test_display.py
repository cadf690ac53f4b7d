"""realpen.display: every function draws into the Axes it is given and touches no global state."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure

import realpen as rp
from realpen import display
from realpen.examples import example_recording_path

plt = pytest.importorskip("matplotlib.pyplot")


@pytest.fixture(scope="module")
def recording():
    return rp.load_recording(example_recording_path())


@pytest.fixture(scope="module")
def analysis(recording):
    return rp.analyze(recording)


@pytest.fixture(scope="module")
def pattern(recording):
    return rp.tactile_pattern(recording, actuator="lra:f0=175,q=8", condition="B")


@pytest.fixture(scope="module")
def loop():
    noise = np.random.default_rng(1).normal(0.0, 0.1, 48000)
    return rp.find_loop(noise, rate=48000)


@pytest.fixture
def no_new_pyplot_figures():
    """Fail the test if it opened or closed a pyplot figure (or switched the backend)."""
    backend, before = matplotlib.get_backend(), plt.get_fignums()
    yield
    assert plt.get_fignums() == before
    assert matplotlib.get_backend() == backend


def own_axes(count: int) -> list[Axes]:
    return list(Figure().subplots(count, 1, squeeze=False)[:, 0])


def test_plot_analysis_draws_into_the_given_ax(analysis, no_new_pyplot_figures):
    (ax,) = own_axes(1)
    assert display.plot_analysis(analysis, ax=ax) is ax
    assert ax.get_xlabel() == "time (s)" and ax.get_ylabel() == "frequency (Hz)"
    points = ax.collections[0].get_offsets()
    assert len(points) == np.isfinite(analysis.frequencies_hz).sum()
    # The selected units are outlined: one marker per peak of a selected unit.
    outlined = ax.collections[1].get_offsets()
    assert len(outlined) == np.isfinite(analysis.frequencies_hz[analysis.selected]).sum()


def test_plot_actuator_draws_response_and_capped_weighting(no_new_pyplot_figures):
    axes = own_axes(2)
    response, weighting = display.plot_actuator(rp.parse_actuator("lra:f0=175,q=8"),
                                                band=(30, 500), cap_db=20, ax=axes)
    assert [response, weighting] == axes
    freqs, weights_db = weighting.get_lines()[1].get_data()
    assert np.max(weights_db) == pytest.approx(20.0)  # the cap
    assert np.min(weights_db) == pytest.approx(0.0, abs=0.05)  # at resonance
    assert freqs[np.argmin(weights_db)] == pytest.approx(175, rel=0.02)


def test_plot_actuator_accepts_a_spec_and_refuses_bad_band():
    response, _ = display.plot_actuator("piezo:f0=300,q=2")
    assert isinstance(response.figure, Figure)
    with pytest.raises(rp.ParameterError, match="^band:"):
        display.plot_actuator("flat", band=(500, 30))
    with pytest.raises(rp.ParameterError, match="^ax:"):
        display.plot_actuator("flat", ax=own_axes(1))


def test_plot_pattern_marks_subpattern_boundaries(pattern, no_new_pyplot_figures):
    axes = own_axes(2)
    wave, spectrogram = display.plot_pattern(pattern, ax=axes)
    assert [wave, spectrogram] == axes
    boundaries = [line.get_xdata()[0] for line in wave.get_lines()[1:]]
    assert boundaries == pytest.approx(np.arange(1, 15) * 100.0)
    assert spectrogram.get_ylabel() == "frequency (Hz)"
    assert wave.get_xlim() == pytest.approx((0, 1500))


def test_plot_pattern_one_view_into_one_ax(pattern, no_new_pyplot_figures):
    (ax,) = own_axes(1)
    assert display.plot_pattern(pattern, ax=ax, views="spectrogram") == [ax]
    with pytest.raises(rp.ParameterError, match="^views:"):
        display.plot_pattern(pattern, ax=ax, views="waterfall")


def test_one_view_of_each_two_panel_plot_into_one_ax(loop, no_new_pyplot_figures):
    (ax,) = own_axes(1)
    assert display.plot_actuator("lra:f0=175,q=8", ax, views="weighting") == [ax]
    assert ax.get_ylabel() == "weight (dB)"
    (ax,) = own_axes(1)
    assert display.plot_sound_loop(loop, ax, views="spectrogram") == [ax]
    assert ax.get_ylabel() == "frequency (kHz)"
    with pytest.raises(rp.ParameterError, match="^views:"):
        display.plot_sound_loop(loop, ax, views="waterfall")


def test_plot_sound_loop_marks_the_wrap(loop, no_new_pyplot_figures):
    axes = own_axes(2)
    wave, spectrogram = display.plot_sound_loop(loop, ax=axes, periods=2)
    period_ms = len(loop.samples) / loop.rate * 1000
    wraps = [line.get_xdata()[0] for line in spectrogram.get_lines()]
    assert wraps == pytest.approx([period_ms])
    assert "level jump" in wave.get_title()


def test_without_ax_a_new_figure_outside_pyplot(analysis, pattern, loop,
                                                no_new_pyplot_figures):
    # The fixture checks that none of these became (or closed) a pyplot figure.
    made = [display.plot_analysis(analysis), *display.plot_actuator("flat"),
            *display.plot_pattern(pattern), *display.plot_sound_loop(loop)]
    assert all(isinstance(ax, Axes) and isinstance(ax.figure, Figure) for ax in made)
    assert made[1].figure is made[2].figure  # the two panels of one call share a figure


@pytest.mark.slow
def test_save_profile_plot_keeps_the_users_figures(tmp_path, no_new_pyplot_figures):
    user = plt.figure()
    try:
        target = display.save_profile_plot(rp.load_profile("pencil"), tmp_path / "pencil.png")
        assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert plt.fignum_exists(user.number)
        with pytest.raises(rp.RealPenError, match="unknown image type"):
            display.save_profile_plot(rp.load_profile("pencil"), tmp_path / "pencil.xyz")
        assert not (tmp_path / "pencil.xyz").exists()
    finally:
        plt.close(user)
