"""A physical friction model of a pen tip on paper, for the pens that ship with RealPen.

No recordings of real pens can be bundled, so the bundled pencil (4B), ballpoint and marker are
made from this model and then pass through the same ``profile build`` pipeline as recordings
would. ``docs/pen-model.md`` writes the model up with its equations; in short, per pen:

1. **Paper roughness.** The paper's height profile along the stroke is a stationary random
   process with a von Kármán spectrum S_h(ν) = σ² · 2ℓ / (1 + (2πνℓ)²)^(H + ½), ν in cycles/m,
   ℓ the fibre-network correlation length, H the Hurst exponent.
2. **Read at the writing speed.** Moving at speed v the tip meets spatial frequency ν = f / v, so
   the height under the tip has the temporal spectrum S_h(f / v) / v.
3. **Contact filter.** The tip averages the surface over its contact width w: a Gaussian
   low-pass exp(−(πνw)²/2) in amplitude.
4. **Hand–pen resonance.** The pen and the hand holding it are a mass m on the contact spring k
   and damper c (ζ = c / 2√(km)): the pen's acceleration follows the surface by the base-excited
   mass-spring-damper, A(f) = ω² (k + jωc) / (k − mω² + jωc) · Y(f).
5. **Stick-slip** (graphite): friction builds over a slip length d and releases, giving pulses
   at f_ss = v / d (jittered) that ring the same resonance in the tangential axis.
6. **Sound.** The same roughness read at audio frequencies through the tip's acoustic contact
   width, plus the tip's own squeak resonance where it has one, radiated by the paper sheet (a
   second-order high-pass at f_rad), with stick-slip clicks for graphite.

Everything is seeded and deterministic.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal

from realpen.io.recording import Recording

__all__ = ["VIBRATION_RATE", "SOUND_RATE", "PaperModel", "PenModel", "PENS", "roughness_amplitude",
           "pen_response", "vibration", "friction_sound"]

VIBRATION_RATE = 1344.0  # Hz, the method's accelerometer rate
SOUND_RATE = 48000  # Hz


@dataclass(frozen=True)
class PaperModel:
    """Paper roughness: RMS height sigma_um (µm), correlation length corr_um (µm), Hurst H."""

    sigma_um: float = 4.0
    corr_um: float = 60.0
    hurst: float = 0.8


@dataclass(frozen=True)
class PenModel:
    """Mechanical and acoustic parameters of one pen (SI units unless named otherwise).

    Attributes:
        name, tool: profile name and tool type.
        contact_um: contact width w of the tip in µm (tactile band).
        mass_g: effective moving mass of pen and hand in g.
        stiffness_n_per_m: contact stiffness k in N/m.
        damping_ratio: ζ of the hand–pen resonance.
        friction: Coulomb friction coefficient μ (tangential / normal).
        stick_slip_mm: slip length d in mm (0: no stick-slip).
        stick_slip_jitter: relative jitter of the stick-slip period.
        sound_contact_um: acoustic contact width in µm (smaller is brighter).
        squeak_hz, squeak_q: the tip's own acoustic resonance (0 Hz: none).
        sound_level: overall sound level (full scale).
        speed_mm_s: writing speed of the model recordings in mm/s.
    """

    name: str
    tool: str
    contact_um: float
    mass_g: float
    stiffness_n_per_m: float
    damping_ratio: float
    friction: float
    stick_slip_mm: float
    stick_slip_jitter: float
    sound_contact_um: float
    squeak_hz: float
    squeak_q: float
    sound_level: float
    speed_mm_s: float = 60.0

    @property
    def resonance_hz(self) -> float:
        """Undamped hand–pen resonance √(k/m) / 2π in Hz."""
        return float(np.sqrt(self.stiffness_n_per_m / (self.mass_g / 1000)) / (2 * np.pi))

    def to_json(self) -> dict:
        """Parameters as a JSON-ready dict (with the derived resonance)."""
        return {**asdict(self), "resonance_hz": round(self.resonance_hz, 3)}


PENS: dict[str, PenModel] = {
    # Soft graphite: a worn flat of graphite, soft contact, stick-slip, bright hiss.
    "pencil": PenModel("pencil", "pencil (4B)", contact_um=150, mass_g=12, stiffness_n_per_m=7000,
                       damping_ratio=0.30, friction=0.35, stick_slip_mm=0.5,
                       stick_slip_jitter=0.2, sound_contact_um=6, squeak_hz=0, squeak_q=0,
                       sound_level=0.30),
    # A rolling steel ball: tiny stiff Hertz contact, little damping, no stick-slip, quiet.
    "ballpoint": PenModel("ballpoint", "ballpoint", contact_um=30, mass_g=10,
                          stiffness_n_per_m=40000, damping_ratio=0.12, friction=0.12,
                          stick_slip_mm=0, stick_slip_jitter=0, sound_contact_um=20, squeak_hz=0,
                          squeak_q=0, sound_level=0.18),
    # A felt nib: wide compliant contact, well damped, a soft squeak.
    "marker": PenModel("marker", "marker", contact_um=170, mass_g=14, stiffness_n_per_m=6000,
                       damping_ratio=0.40, friction=0.45, stick_slip_mm=0, stick_slip_jitter=0,
                       sound_contact_um=12, squeak_hz=1400, squeak_q=4, sound_level=0.25),
}


def _shaped_noise(rng: np.random.Generator, frames: int, rate: float,
                  amplitude_of: callable) -> np.ndarray:
    """Gaussian noise whose amplitude spectrum follows ``amplitude_of(f)`` (f in Hz)."""
    spectrum = np.fft.rfft(rng.standard_normal(frames))
    freqs = np.fft.rfftfreq(frames, 1.0 / rate)
    shaped = np.fft.irfft(spectrum * amplitude_of(freqs), n=frames)
    return shaped


def roughness_amplitude(freqs_hz: np.ndarray, paper: PaperModel, speed_mm_s: float,
                        contact_um: float) -> np.ndarray:
    """√ of the height spectrum under the tip (m/√Hz, up to a constant) at temporal frequency f.

    S_h(ν) read at ν = f / v, times the tip's Gaussian contact filter.
    """
    v = speed_mm_s / 1000.0
    nu = freqs_hz / v
    ell = paper.corr_um * 1e-6
    psd = (paper.sigma_um * 1e-6) ** 2 * 2 * ell / (1 + (2 * np.pi * nu * ell) ** 2) ** (paper.hurst + 0.5)
    contact = np.exp(-0.5 * (np.pi * nu * contact_um * 1e-6) ** 2)
    return np.sqrt(psd / v) * contact


def pen_response(freqs_hz: np.ndarray, pen: PenModel) -> np.ndarray:
    """|A/Y|: acceleration of the pen per unit surface displacement (1/s²), base-excited."""
    omega = 2 * np.pi * freqs_hz
    m = pen.mass_g / 1000
    k = pen.stiffness_n_per_m
    c = 2 * pen.damping_ratio * np.sqrt(k * m)
    return np.abs(omega ** 2 * (k + 1j * omega * c) / (k - m * omega ** 2 + 1j * omega * c))


def _stick_slip_train(rng: np.random.Generator, frames: int, rate: float, pen: PenModel) -> np.ndarray:
    """Unit impulses at the stick-slip releases (period d / v, jittered)."""
    train = np.zeros(frames)
    if pen.stick_slip_mm <= 0:
        return train
    period = pen.stick_slip_mm / pen.speed_mm_s
    t = rng.uniform(0, period)
    while t < frames / rate:
        train[int(t * rate)] += rng.uniform(0.6, 1.4)
        t += period * (1 + pen.stick_slip_jitter * rng.uniform(-1, 1))
    return train


def _resonance(pen: PenModel, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Digital second-order resonator at the hand–pen resonance (for stick-slip pulses)."""
    omega = 2 * np.pi * pen.resonance_hz
    analog_b, analog_a = [omega ** 2], [1, 2 * pen.damping_ratio * omega, omega ** 2]
    return signal.bilinear(analog_b, analog_a, fs=rate)


def _writing_envelope(frames: int, rate: float, rng: np.random.Generator) -> np.ndarray:
    """Slow ±10 % fluctuation of the hand's speed and force, with pen-down and lift ramps."""
    t = np.arange(frames) / rate
    phase = rng.uniform(0, 2 * np.pi, 2)
    envelope = (1 + 0.07 * np.sin(2 * np.pi * 0.9 * t + phase[0])
                + 0.03 * np.sin(2 * np.pi * 2.1 * t + phase[1]))
    ramp = np.clip(t / 0.05, 0, 1) * np.clip((t[-1] - t) / 0.05, 0, 1)
    return envelope * ramp


def vibration(pen: PenModel, paper: PaperModel = PaperModel(), duration_s: float = 6.0,
              seed: int = 0) -> Recording:
    """Three-axis acceleration (m/s², 1344 Hz) of ``pen`` writing on ``paper``.

    z is normal to the paper (roughness through the hand–pen resonance), x tangential along the
    stroke (friction μ times the normal force fluctuation, plus stick-slip), y lateral (a little
    of both). A 0.02 m/s² sensor noise floor is added.
    """
    rng = np.random.default_rng(seed)
    rate = VIBRATION_RATE
    frames = int(round(duration_s * rate))
    normal = _shaped_noise(rng, frames, rate, lambda f: roughness_amplitude(
        f, paper, pen.speed_mm_s, pen.contact_um) * pen_response(f, pen)) * np.sqrt(rate / 2)
    tangential = pen.friction * normal
    train = _stick_slip_train(rng, frames, rate, pen)
    if train.any():
        b, a = _resonance(pen, rate)
        pulses = signal.lfilter(b, a, train)
        tangential = tangential + 0.6 * np.std(normal) * pulses / (np.std(pulses) + 1e-12)
    lateral = 0.3 * tangential + 0.2 * normal
    envelope = _writing_envelope(frames, rate, rng)
    axes = np.column_stack([tangential, lateral, normal]) * envelope[:, None]
    axes += 0.02 * rng.standard_normal(axes.shape)
    return Recording(axes, rate, ("x", "y", "z"), units="m/s^2",
                     source=f"realpen pen model: {pen.name} on paper, seed {seed}")


def friction_sound(pen: PenModel, paper: PaperModel = PaperModel(), duration_s: float = 4.0,
                   seed: int = 0, rate: int = SOUND_RATE, radiation_hz: float = 400.0) -> np.ndarray:
    """Friction sound of ``pen`` writing on ``paper``: mono, full scale ±1, at ``rate`` Hz.

    The roughness is read through the tip's acoustic contact width, shaped by the tip's squeak
    resonance if it has one and by the paper sheet's radiation (second-order high-pass at
    ``radiation_hz``); graphite adds stick-slip clicks. Peak level is ``pen.sound_level``.
    """
    rng = np.random.default_rng(seed + 1_000_003)
    frames = int(round(duration_s * rate))

    def shape(f: np.ndarray) -> np.ndarray:
        amplitude = roughness_amplitude(f, paper, pen.speed_mm_s, pen.sound_contact_um) * (2 * np.pi * f)
        r = f / radiation_hz
        amplitude = amplitude * r ** 2 / np.sqrt((1 - r ** 2) ** 2 + (r / 0.7) ** 2)
        if pen.squeak_hz > 0:
            s = f / pen.squeak_hz
            detuning = s - 1 / np.maximum(s, 1e-9)
            amplitude = amplitude * (1 + 3 / np.sqrt(1 + pen.squeak_q ** 2 * detuning ** 2))
        return amplitude

    sound = _shaped_noise(rng, frames, rate, shape)
    train = _stick_slip_train(rng, frames, rate, pen)
    if train.any():
        b, a = signal.butter(2, [2000, 9000], btype="bandpass", fs=rate)
        clicks = signal.lfilter(b, a, train)
        sound = sound + 0.5 * np.std(sound) * clicks / (np.std(clicks) + 1e-12)
    sound *= _writing_envelope(frames, rate, rng)
    return sound * (pen.sound_level / np.max(np.abs(sound)))
