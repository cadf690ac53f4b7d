"""Figures of a pen profile, like the method's Figure 8: the tactile pattern in time and as a
spectrogram, and the spectrum of the friction-sound unit."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

from realpen.errors import fail  # noqa: E402
from realpen.io.files import atomic_path  # noqa: E402
from realpen.profile.bundle import PenProfile  # noqa: E402


def profile_figure(profile: PenProfile) -> "matplotlib.figure.Figure":
    """Three panels: tactile pattern (time), its spectrogram (0–700 Hz), sound unit spectrum."""
    tactile, rate = profile.tactile, profile.meta.tactile.rate
    sound, sound_rate = profile.sound, profile.meta.sound.rate
    figure, (wave, spec, audio) = plt.subplots(3, 1, figsize=(9, 9), constrained_layout=True)
    t_ms = np.arange(len(tactile)) / rate * 1000
    wave.plot(t_ms, tactile, lw=0.6, color="#334")
    sub_ms = profile.meta.tactile.subpattern_ms
    for boundary in np.arange(sub_ms, t_ms[-1], sub_ms):
        wave.axvline(boundary, color="#c44", lw=0.5, alpha=0.5)
    wave.set(xlim=(0, t_ms[-1]), xlabel="time (ms)", ylabel="drive (full scale)",
             title=f"{profile.name} — tactile pattern ({len(profile.meta.tactile.subpatterns)} "
                   f"sub-patterns of {sub_ms:g} ms, actuator {profile.meta.actuator.spec})")
    nperseg = int(rate * 0.05)
    freqs, times, power = signal.spectrogram(tactile, rate, nperseg=nperseg,
                                             noverlap=nperseg * 3 // 4, nfft=4 * nperseg)
    keep = freqs <= 700
    spec.pcolormesh(times * 1000, freqs[keep], 10 * np.log10(power[keep] + 1e-12),
                    shading="auto", cmap="magma")
    spec.set(xlabel="time (ms)", ylabel="frequency (Hz)", title="tactile pattern spectrogram (dB)")
    freqs, psd = signal.welch(sound, sound_rate, nperseg=min(len(sound), 4096))
    audio.semilogx(freqs[1:], 10 * np.log10(psd[1:] + 1e-20), color="#246")
    audio.set(xlim=(20, sound_rate / 2), xlabel="frequency (Hz)", ylabel="PSD (dB re FS²/Hz)",
              title=f"friction-sound unit spectrum ({profile.meta.sound.unit_ms:g} ms "
                    f"{profile.meta.sound.mode})")
    audio.grid(True, which="both", alpha=0.3)
    return figure


def save_profile_plot(profile: PenProfile, target: str | os.PathLike) -> None:
    """Draw :func:`profile_figure` into a PNG (or any matplotlib format by suffix), atomically."""
    kind = Path(target).suffix.lower().lstrip(".")
    supported = plt.gcf().canvas.get_supported_filetypes()
    plt.close("all")
    if kind not in supported:
        raise fail(target, f"unknown image type '.{kind}' (use one of "
                           f"{', '.join('.' + k for k in sorted(supported))})")
    figure = profile_figure(profile)
    try:
        with atomic_path(target) as tmp:
            figure.savefig(tmp, dpi=110, format=kind)
    finally:
        plt.close(figure)
