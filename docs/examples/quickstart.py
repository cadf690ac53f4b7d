"""RealPen quickstart: from a pen recording to a tactile pattern, a figure and an AHAP file.

Run it as a script (``python docs/examples/quickstart.py [OUTPUT_FOLDER]``) or cell by cell in a
notebook or an editor that understands ``# %%`` cells. It writes ``quickstart.png`` and
``pattern-b.ahap`` into OUTPUT_FOLDER (default: ``quickstart-output``).
"""

# %% Setup: one import gives the whole API; the output folder comes from the command line.
import sys
from pathlib import Path

from matplotlib.figure import Figure  # a figure of our own; in a notebook plt.subplots is fine

import realpen as rp
from realpen.examples import example_recording_path

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("quickstart-output")
out.mkdir(parents=True, exist_ok=True)

# %% Load the bundled example: a synthetic 3-axis accelerometer recording of a pen on paper
# (12 s at 1344 Hz, m/s²). Any WAV/FLAC, CSV or NPZ recording loads the same way.
recording = rp.load_recording(example_recording_path())
print(recording)

# %% Take a 4 s excerpt (from 2 s to 6 s). Every study condition, A to F, works from 4 s:
# A/B/C split a 1500 ms stretch into 15 units of 100 ms, D/E/F analyse the same stretch whole.
rate = recording.rate
excerpt = recording.with_samples(recording.samples[int(2 * rate):int(6 * rate)],
                                 "excerpt:2-6s")
print(excerpt)

# %% Analyse: axes → one (DFT321), 30 Hz high-pass, 100 ms units, top 10 peaks per unit,
# and the 15 consecutive units (first and last excluded) that the pattern will use.
analysis = rp.analyze(excerpt, unit_ms=100, top=10)
print(analysis)

# %% Build two tactile patterns for a linear resonant actuator (175 Hz, Q = 8):
# condition B (the method's choice): 10 frequencies × 15 sub-patterns of 100 ms;
# condition E: the same 10-frequency budget in one 1500 ms pattern with no fluctuation.
pattern_b = rp.tactile_pattern(excerpt, actuator="lra:f0=175,q=8", condition="B")
pattern_e = rp.tactile_pattern(excerpt, actuator="lra:f0=175,q=8", condition="E")
print(pattern_b)
print(pattern_e)
print("first sub-pattern of B:", pattern_b.subpatterns[0][0], "...")

# %% One figure, two panels: the analysis (the method's Figure 4b; the shaded units are the
# ones pattern B was made from) and pattern B's spectrogram (Figure 8), where the frequency
# content changes at every 100 ms sub-pattern boundary (dotted).
figure = Figure(figsize=(9, 7), layout="constrained")
top, bottom = figure.subplots(2, 1)
rp.display.plot_analysis(analysis, ax=top)
rp.display.plot_pattern(pattern_b, ax=bottom, views="spectrogram")
bottom.set_title("pattern B (condition B, lra:f0=175,q=8): spectrogram over one loop")
figure.savefig(out / "quickstart.png", dpi=120)

# %% Export pattern B as Apple Core Haptics (AHAP) for an iPhone or iPad.
rp.export("ahap", out / "pattern-b.ahap", pattern_b)
print("wrote", out / "quickstart.png", "and", out / "pattern-b.ahap")
