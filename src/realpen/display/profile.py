"""Figures of a pen profile, like the method's Figure 8: the tactile pattern in time and as a
spectrogram, and the spectrum of the friction-sound unit (the plot of ``realpen profile show``)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backend_bases import FigureCanvasBase
from matplotlib.figure import Figure

from realpen.display.axes import axes_list, db
from realpen.display.pattern import plot_pattern
from realpen.errors import fail

__all__ = ["profile_figure", "save_profile_plot", "plot_sound_spectrum"]


def _sound_of(profile) -> tuple[np.ndarray, float]:
    """The profile's sound unit and its rate in Hz."""
    loop = profile.sound_loop
    return np.asarray(loop.samples, dtype=np.float64).reshape(-1), float(loop.rate)


def plot_sound_spectrum(samples: np.ndarray, rate: float, ax: Axes | None = None, *,
                        title: str = "friction-sound unit spectrum") -> Axes:
    """Welch power spectral density of a sound, on a log-frequency axis from 20 Hz.

    Args:
        samples: the sound, shape (frames,), full scale ±1.
        rate: its rate in Hz.
        ax: the Axes to draw into; None makes a new figure (not a pyplot one).
        title: the panel's title.

    Returns:
        The Axes drawn into.

    Example:
        >>> import numpy as np
        >>> from realpen.display import plot_sound_spectrum
        >>> ax = plot_sound_spectrum(np.random.default_rng(0).normal(0, 0.1, 48000), 48000)
        >>> ax.get_xlabel()
        'frequency (Hz)'
    """
    from scipy import signal

    (ax,) = axes_list(ax, 1, (8, 3), parameter="ax")
    x = np.asarray(samples, dtype=np.float64).reshape(-1)
    freqs, psd = signal.welch(x, rate, nperseg=min(len(x), 4096))
    ax.semilogx(freqs[1:], db(psd[1:]), color="#246")
    ax.set(xlim=(20, rate / 2), xlabel="frequency (Hz)", ylabel="PSD (dB re FS²/Hz)",
           title=title)
    ax.grid(True, which="both", alpha=0.3)
    return ax


def profile_figure(profile, ax: Sequence[Axes] | None = None) -> Figure:
    """Three panels: tactile pattern (time), its spectrogram (to 700 Hz), sound unit spectrum.

    Args:
        profile: a :class:`realpen.profile.PenProfile` (see :func:`realpen.load_profile`).
        ax: three Axes to draw into; None makes a new figure (not a pyplot one).

    Returns:
        The figure of the (first) Axes.

    Example:
        >>> import realpen as rp
        >>> from realpen.display import profile_figure
        >>> figure = profile_figure(rp.load_profile("pencil"))
        >>> len(figure.axes) >= 3
        True
    """
    wave, spec, audio = axes_list(ax, 3, (9, 9), "ax")
    plot_pattern(profile.pattern, [wave, spec], fmax_hz=700.0)
    wave.set_title(f"{profile.name} — {wave.get_title()}, actuator {profile.actuator.spec}")
    sound, rate = _sound_of(profile)
    section = profile.meta.sound
    plot_sound_spectrum(sound, rate, audio, title=f"friction-sound unit spectrum "
                                                   f"({section.unit_ms:g} ms {section.mode})")
    return wave.figure


def save_profile_plot(profile, target: str | os.PathLike) -> Path:
    """Draw :func:`profile_figure` into a PNG (or any matplotlib format by suffix), atomically.

    Uses a figure of its own, never pyplot: the caller's figures and backend are untouched.

    Returns:
        The path written.

    Raises:
        RealPenError: an image type matplotlib cannot write (named by the suffix).
    """
    from realpen.io.files import atomic_path

    target = Path(target)
    kind = target.suffix.lower().lstrip(".")
    supported = FigureCanvasBase.get_supported_filetypes()
    if kind not in supported:
        raise fail(target, f"unknown image type '.{kind}' (use one of "
                           f"{', '.join('.' + k for k in sorted(supported))})")
    figure = profile_figure(profile)
    with atomic_path(target) as tmp:
        figure.savefig(tmp, dpi=110, format=kind)
    return target
