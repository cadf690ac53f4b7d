"""Figures with matplotlib: analyses, actuators, patterns, sound loops and profiles.

Every function draws into a given ``ax`` (or ``axes`` for several panels), or makes its own
figure when that is None, and returns what it drew on. Nothing here changes global matplotlib
state: no backend switch, no ``rcParams`` change, and no ``pyplot`` — a figure made here is a
plain :class:`matplotlib.figure.Figure`, so it never closes, replaces or adds to the user's
pyplot figures. In a notebook, show a figure by making it the cell's value (``ax.figure``).

- :func:`plot_analysis` — principal frequencies per unit (the method's Figure 4b).
- :func:`plot_actuator` — actuator response |H(f)| and the capped weighting (Figure 2c–d).
- :func:`plot_measured_actuator` — a measured response with its fit, coherence, distortion and
  weighting (Figure 2c from ``realpen actuator measure``); :func:`plot_flatness` — how flat an
  equalised multisine arrives (``realpen actuator verify``).
- :func:`plot_pattern` — a tactile pattern in time and its spectrogram (Figure 8).
- :func:`plot_sound_loop` — a sound loop's waveform and spectrogram across its wrap.
- :func:`profile_figure`, :func:`save_profile_plot` — a pen profile (the plot of ``realpen profile show``).

Shared pieces: :mod:`~realpen.display.axes` (axes to draw into, spectrograms, dB),
:mod:`~realpen.display.charts` (panels, means with intervals, participants' values — what the
study figures of :mod:`realpen.stats.figures` draw with) and :mod:`~realpen.display.images`
(image types, reproducible bytes, atomic writes).

May import: :mod:`realpen.errors` and the library layers below it (:mod:`realpen.io`,
:mod:`realpen.dsp`, :mod:`realpen.tactile`, :mod:`realpen.sound`, :mod:`realpen.profile`);
never :mod:`realpen.study`, :mod:`realpen.stats`, :mod:`realpen.live` or :mod:`realpen.cli`
(what knows a study draws in :mod:`realpen.stats`).
"""

from realpen.display.actuator import plot_actuator, plot_flatness, plot_measured_actuator
from realpen.display.analysis import plot_analysis
from realpen.display.pattern import plot_pattern
from realpen.display.profile import plot_sound_spectrum, profile_figure, save_profile_plot
from realpen.display.sound import plot_sound_loop

__all__ = ["plot_analysis", "plot_actuator", "plot_measured_actuator", "plot_flatness",
           "plot_pattern", "plot_sound_loop",
           "plot_sound_spectrum", "profile_figure", "save_profile_plot"]
