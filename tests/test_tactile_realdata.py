"""The tactile pipeline on real stylus-on-paper vibration (Penn HaTT models of paper surfaces).

Data: Culbertson, Lopez Delgado & Kuchenbecker, Penn Haptic Texture Toolkit (2014), read from
../shared/data/hatt_models; research use only, never bundled.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from realpen.datasets.hatt import load_hatt, synthesize
from realpen.tactile.actuator import parse_actuator
from realpen.tactile.build import build_pattern
from realpen.tactile.conditions import TactileParams

PAPERS = ["Book", "Resume Paper", "Tissue Paper", "Playing Card", "Cardboard", "Paper Bag"]


@pytest.mark.parametrize("paper", PAPERS)
def test_pattern_from_a_paper_model(hatt_dir, paper):
    models = load_hatt(hatt_dir / f"Models_{paper}.xml")
    speed, force = 120.0, 1.5
    recording = synthesize(models, speed, force, duration_s=4.0, seed=1)
    params = TactileParams(analysis_rate=1344)  # resampled to the method's rate
    pattern = build_pattern(recording, parse_actuator("lra:f0=175,q=4"), params)
    assert pattern.duration_s == pytest.approx(1.5)
    assert len(pattern.subpatterns) == 15 and all(len(s) == 10 for s in pattern.subpatterns)
    freqs = np.array([c.frequency_hz for s in pattern.subpatterns for c in s])
    assert freqs.min() >= 30 and freqs.max() <= 500  # the model has nothing above its Nyquist
    # The strongest principal frequencies lie where the model's own spectrum is strong.
    model = models.model_at(speed, force)
    grid = np.linspace(30, 495, 1000)
    _, response = signal.freqz(model.gain * model.ma, model.ar, worN=grid, fs=models.rate)
    level_db = 20 * np.log10(np.abs(response) + 1e-30)
    strongest = np.array([s[0].frequency_hz for s in pattern.subpatterns])
    at_strongest = np.interp(strongest, grid, level_db)
    assert np.median(at_strongest) > level_db.max() - 10
    # And the loop is seamless.
    steps = np.abs(np.diff(np.concatenate([pattern.samples, pattern.samples[:1]])))
    seams = np.arange(1, 16) * 800 - 1
    assert steps[seams].max() <= np.delete(steps, seams).max()
