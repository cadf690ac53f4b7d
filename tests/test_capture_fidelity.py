"""End to end: the modelled pencil felt by the simulated pen's LIS3DH, captured with
``realpen.device.record``, gives the recording and the pattern the source gives directly.

The capture chain is all there: the firmware's driver draining the register-level FIFO over the
simulated bus, SAMPLES over the pseudo-terminal, the host placing the blocks and estimating the
sensor's true rate (1.3 % off its nominal 1344 Hz) from the pen's clock, 12-bit quantisation.
The sensor's own noise is set to 0 here so that the test measures the capture and not the
noise floor (a real LIS3DH's ~5 mg fills in what the model's spectrum has below it;
docs/recording.md, "What the simulator shows", gives both).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import resample

import realpen as rp
from realpen.device.capture import record
from realpen.device.client import PenClient
from realpen.device.sim import SimPen
from realpen.device.transport import open_transport
from realpen.dsp.filters import prepare
from realpen.io.recording import Recording, load_recording, save_npz
from realpen.pens.build import write_model_recordings
from realpen.tactile.fidelity import loop_psd, signal_psd, weighted_lsd

pytestmark = pytest.mark.firmware


def test_capture_adds_almost_nothing_to_the_modelled_pencil(tmp_path):
    vibration, _sound = write_model_recordings("pencil", tmp_path)
    model = load_recording(vibration)  # m/s² in a float WAV
    source = Recording(model.samples, model.rate, model.axes, units="m/s^2", source="pencil")
    save_npz(source, tmp_path / "pencil.npz")
    with SimPen(accelerometer=tmp_path / "pencil.npz", noise_g=0.0) as pen, \
            PenClient(open_transport(pen.port)) as client:
        capture = record(client, source.duration + 0.3)
        true_rate = pen.sensor_rate_hz
    assert capture.gaps == [] and capture.rate_hz == pytest.approx(true_rate, rel=1e-3)
    # The sensor starts at the source's first sample: one loop of it is the source as the
    # sensor sampled it. Directly: the same source put on the sensor's true grid.
    frames = round(len(source.samples) * true_rate / source.rate)
    captured = capture.to_recording()
    captured = Recording(captured.samples[:frames], captured.rate, captured.axes,
                         units=captured.units, source="capture")
    direct = Recording(resample(source.samples, frames, axis=0), true_rate, source.axes,
                       units="m/s^2", source="direct")

    # The recordings: the weighted log-spectral distance of what the pipeline analyses.
    ours, theirs = prepare(captured), prepare(direct)
    recording_lsd = weighted_lsd(signal_psd(ours.mono, ours.rate),
                                 signal_psd(theirs.mono, theirs.rate))
    assert recording_lsd < 0.5

    # The patterns, from the same units (the middle run: the steadiest run of a model this
    # steady is a near-tie that any change of a sample may swing). Their spectral envelopes
    # (third octaves) are compared: the top-10 peaks of a 100 ms unit of this noise-like
    # vibration are themselves near-ties, which resampling alone changes.
    from_capture = rp.tactile_pattern(captured, selection="middle")
    from_source = rp.tactile_pattern(direct, selection="middle")
    assert np.array_equal(from_capture.analysis.selected, from_source.analysis.selected)
    pattern_lsd = weighted_lsd(loop_psd(from_capture.samples, from_capture.rate),
                               loop_psd(from_source.samples, from_source.rate),
                               smooth_octaves=1 / 3)
    assert pattern_lsd < 0.5, (recording_lsd, pattern_lsd)
