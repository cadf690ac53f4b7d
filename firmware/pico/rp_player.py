"""The pen's player: loops a pattern of int16 samples with a ramped gain and playback rate.

Plain MicroPython (it runs unchanged under CPython). The player is specified sample for sample
in docs/protocol.md ("What the pen plays"); this is that specification in code:

- ``amp`` is an integer 0 … 32767 (Q15). Its target is ``gain * gain_cap // 65535`` while
  playing, else 0. Every state change ramps linearly from the current ``amp`` to the target over
  ``N = max(fade_ms, 5) * sample_rate // 1000`` samples, from the first sample of the next block
  :meth:`Player.fill` renders: ``amp_k = amp_0 + (target - amp_0) * k // N`` for k = 1 … N.
- The playback rate (Q12, 4096 = as stored) ramps the same way over 5 ms, from each state whose
  rate differs from the current target.
- For each sample, in this order: (1) the ramps take their next step; (2) if ``amp`` is 0 and
  the pen is not playing (idle), or there is no pattern yet, the position goes back to 0 and a
  committed pattern, if any, is swapped in, and if that leaves it idle (or without a pattern)
  the sample is 0; (3) otherwise the sample is ``(p * amp) >> 15``, ``p`` the pattern at the
  position (linear interpolation between ``pattern[i]`` and ``pattern[i + 1]`` by the
  position's fraction, below), and the position advances by ``rate << 4`` in Q16.
- A committed pattern replaces the playing one when the position wraps (the new pattern starts
  at position 0), or at once when idle or when there is no pattern yet. Before any pattern the
  output is silence.

The position is kept as an integer index and a 16-bit fraction rather than one Q16 number, the
same value, so that no intermediate exceeds a MicroPython small int on a 32-bit port (2**30):
``pattern_length << 16`` would be 2**30 for a 32 KB pattern. Interpolation is
``p = p0 + ((p1 - p0) * (frac >> 2)) >> 14`` for the same reason ((p1 - p0) * frac would need
33 bits); with ``frac == 0`` it is ``p0`` exactly. The fraction is 0 from a stroke's start
until a rate other than 4096 takes effect (and keeps its value after that until the next stop),
so a stroke at rate 4096 throughout plays the pattern's own samples unchanged. Ramps are
stepped with a quotient and remainder instead of multiplying ``(target - amp_0) * k`` (which
can exceed 2**30 for long fades); the values are identical.

:meth:`Player.fill` allocates nothing: the two pattern buffers (the one playing and the one an
upload writes into) are allocated once, a commit only swaps them, and the state a host sets is
handed over as one tuple the audio loop reads. So it can run from an I2S interrupt handler and
under ``micropython.heap_lock()``.
"""

from array import array

GAIN_ONE = 65535  # SET_STATE gain for the capped full drive
RATE_ONE = 4096  # Q12 playback-rate factor that plays the pattern as stored
RATE_MIN = 1024
RATE_MAX = 16384
AMP_MAX = 32767  # Q15 full scale
MIN_FADE_MS = 5  # every ramp (gain and rate) lasts at least this long


class Player:
    """Loops one pattern (int16 samples at ``sample_rate`` Hz) at a ramped amplitude and rate.

    ``max_pattern_bytes``: the largest pattern it can hold (2 bytes a sample); two buffers of that
    size are allocated here and never again. ``gain_cap``: the amplitude (Q15, 0 … 32767) that
    full gain (65535) drives, the firmware's limit for the amplifier and actuator.
    """

    def __init__(self, sample_rate=8000, max_pattern_bytes=32768, gain_cap=AMP_MAX):
        if not 0 <= gain_cap <= AMP_MAX:
            raise ValueError("gain_cap must be 0 ... 32767")
        self.sample_rate = sample_rate
        self.max_samples = max_pattern_bytes // 2
        self.gain_cap = gain_cap
        zeros = bytes(2 * self.max_samples)
        self._bufs = (array("h", zeros), array("h", zeros))
        self._active = 0  # index of the playing buffer in _bufs; the other is the staging one
        self.length = 0  # samples of the playing pattern; 0 = no pattern yet (silence)
        self.pattern_id = -1  # id of the playing pattern, -1 before any
        # Position: index into the pattern and a Q16 fraction (together the Q16 position).
        self.index = 0
        self.frac = 0
        # Amplitude ramp: amp = amp0 + q, with q stepped as floor((target - amp0) * k / n).
        self.amp = 0
        self.playing = 0
        self._amp0 = 0
        self._amp_target = 0
        self._amp_k = 0
        self._amp_n = 0
        self._amp_q = 0
        self._amp_r = 0
        self._amp_dq = 0
        self._amp_dr = 0
        # Rate ramp, the same way.
        self.rate = RATE_ONE
        self._rate0 = RATE_ONE
        self._rate_target = RATE_ONE
        self._rate_k = 0
        self._rate_n = 0
        self._rate_q = 0
        self._rate_r = 0
        self._rate_dq = 0
        self._rate_dr = 0
        # Hand-over from the protocol side (main loop) to fill (audio interrupt): one reference
        # each, assigned whole, so fill never sees half a state.
        self._request = None  # (playing, target amp, target rate, amp ramp samples, rate ramp)
        self._next = None  # (length in samples, id) of a committed pattern awaiting its swap
        # What the last fill did, for the firmware to report (it may not allocate either).
        self.applied = False  # a state request took effect at this block's first sample
        self.swap_at = -1  # sample within this block where a new pattern started, or -1
        self.swaps = 0  # patterns swapped in so far

    # -- protocol side (may allocate) -------------------------------------------------------

    def set_state(self, playing, gain, rate=RATE_ONE, fade_ms=MIN_FADE_MS):
        """Ask for a new state from the next block on: ``playing`` 0/1, ``gain`` 0 … 65535,
        ``rate`` Q12 (1024 … 16384), ``fade_ms`` the ramp time in ms (at least 5).

        The latest request before a block wins. ValueError if a value is out of range.
        """
        if playing not in (0, 1) or not 0 <= gain <= GAIN_ONE or not RATE_MIN <= rate <= RATE_MAX:
            raise ValueError("state value out of range")
        if fade_ms < 0:
            raise ValueError("fade_ms must be >= 0")
        target = gain * self.gain_cap // GAIN_ONE if playing else 0
        amp_n = max(fade_ms, MIN_FADE_MS) * self.sample_rate // 1000
        rate_n = MIN_FADE_MS * self.sample_rate // 1000
        self._request = (playing, target, rate, max(amp_n, 1), max(rate_n, 1))

    def staging(self):
        """The buffer an upload writes into (``array('h')`` of ``max_samples``).

        Starting an upload cancels a committed pattern that has not started playing yet (the
        staging buffer holds it): the pen keeps playing the one it plays.
        """
        self._next = None
        return self._bufs[1 - self._active]

    def commit(self, length, pattern_id):
        """Play the staging buffer's first ``length`` samples from the next wrap (or at once when
        idle): the pattern named ``pattern_id``."""
        if not 0 < length <= self.max_samples:
            raise ValueError("pattern length out of range")
        self._next = (length, pattern_id)

    def samples(self):
        """The playing pattern's samples (a memoryview of its buffer; empty before any)."""
        return memoryview(self._bufs[self._active])[:self.length]

    @property
    def amp_target(self):
        """The amplitude (Q15) the current ramp heads for."""
        return self._amp_target

    @property
    def pending(self):
        """True while a committed pattern waits for its swap."""
        return self._next is not None

    def idle(self):
        """True when nothing sounds and the position is at the pattern's start."""
        return self.amp == 0 and not self.playing and self._request is None

    # -- audio side (allocates nothing) -----------------------------------------------------

    def fill(self, buf):
        """Render ``len(buf)`` samples into ``buf`` (a preallocated ``array('h')``)."""
        self.swap_at = -1
        self.applied = False
        if self._next is not None and (self.length == 0 or (self.amp == 0 and not self.playing)):
            # Committed while idle: it swaps in at once, before a SET_STATE that arrived in the
            # same block can start the old pattern playing.
            self._swap(0)
        request = self._request
        if request is not None:
            self._request = None
            self.applied = True
            playing, target, rate_target, amp_n, rate_n = request
            self.playing = playing
            amp0 = self.amp
            self._amp0 = amp0
            self._amp_target = target
            self._amp_k = 0
            self._amp_n = amp_n
            self._amp_q = 0
            self._amp_r = 0
            self._amp_dq = (target - amp0) // amp_n
            self._amp_dr = (target - amp0) % amp_n
            if rate_target != self._rate_target:
                rate0 = self.rate
                self._rate0 = rate0
                self._rate_target = rate_target
                self._rate_k = 0
                self._rate_n = rate_n
                self._rate_q = 0
                self._rate_r = 0
                self._rate_dq = (rate_target - rate0) // rate_n
                self._rate_dr = (rate_target - rate0) % rate_n

        # Locals for speed; written back at the end.
        pattern = self._bufs[self._active]
        length = self.length
        index = self.index
        frac = self.frac
        amp = self.amp
        playing = self.playing
        amp_k = self._amp_k
        amp_n = self._amp_n
        amp_q = self._amp_q
        amp_r = self._amp_r
        amp_dq = self._amp_dq
        amp_dr = self._amp_dr
        amp0 = self._amp0
        rate = self.rate
        rate_k = self._rate_k
        rate_n = self._rate_n
        rate_q = self._rate_q
        rate_r = self._rate_r
        rate_dq = self._rate_dq
        rate_dr = self._rate_dr
        rate0 = self._rate0

        for j in range(len(buf)):
            if amp_k < amp_n:
                amp_k += 1
                amp_q += amp_dq
                amp_r += amp_dr
                if amp_r >= amp_n:
                    amp_r -= amp_n
                    amp_q += 1
                amp = amp0 + amp_q
            if rate_k < rate_n:
                rate_k += 1
                rate_q += rate_dq
                rate_r += rate_dr
                if rate_r >= rate_n:
                    rate_r -= rate_n
                    rate_q += 1
                rate = rate0 + rate_q
            if length == 0 or (amp == 0 and not playing):
                index = 0
                frac = 0
                if self._next is not None:
                    self._swap(j)
                    length = self.length
                    pattern = self._bufs[self._active]
                if length == 0 or (amp == 0 and not playing):
                    buf[j] = 0
                    continue
            p = pattern[index]
            if frac:
                following = index + 1
                if following == length:
                    following = 0
                p += ((pattern[following] - p) * (frac >> 2)) >> 14
            buf[j] = (p * amp) >> 15
            frac += rate << 4
            index += frac >> 16
            frac &= 0xFFFF
            if index >= length:
                if self._next is not None:
                    self._swap(j + 1)
                    length = self.length
                    pattern = self._bufs[self._active]
                    index = 0
                    frac = 0
                else:
                    while index >= length:
                        index -= length

        self.index = index
        self.frac = frac
        self.amp = amp
        self._amp_k = amp_k
        self._amp_q = amp_q
        self._amp_r = amp_r
        self.rate = rate
        self._rate_k = rate_k
        self._rate_q = rate_q
        self._rate_r = rate_r

    def _swap(self, at):
        # The staging buffer becomes the playing one (at sample ``at`` of this block).
        length, pattern_id = self._next
        self._next = None
        self._active = 1 - self._active
        self.length = length
        self.pattern_id = pattern_id
        self.swap_at = at
        self.swaps += 1
