/* The RealPen pattern player in plain C99: loops an int16 pattern with a smoothed gain and
 * playback rate, in integer arithmetic only, exactly as the contract's player semantics (the
 * MicroPython firmware's rp_player follows the same rules; docs/protocol.md):
 *
 *  - amp is Q15 (0 … 32767); its target is gain * gain_cap / 65535 (floor) when playing, else 0;
 *  - every SET_STATE starts a linear ramp from the current amp to the target over
 *    N = max(fade_ms, 5) * sample_rate / 1000 samples (floor), from the first sample of the next
 *    block rendered: amp_k = amp0 + floor((target - amp0) * k / N), k = 1 … N;
 *  - out = (pattern[i] * amp) >> 15 (arithmetic shift, i.e. floor);
 *  - the position is Q16 and advances by rate_q12 << 4 a sample; a change of rate ramps the
 *    same way over 5 ms; at a whole-sample position the output is the pattern's sample exactly,
 *    between samples it is interpolated linearly (a + ((b - a) * (frac >> 2) >> 14));
 *  - when amp reaches 0 with playing = 0 the position resets to 0;
 *  - a loaded pattern replaces the playing one at its next wrap, or at once when idle (or when
 *    there is none); before any pattern the output is silence.
 *
 * The player never allocates and does not own the pattern memory: the caller keeps a loaded
 * pattern alive until rp_player_active / rp_player_next no longer return it.
 */
#ifndef REALPEN_PLAYER_H
#define REALPEN_PLAYER_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define RP_GAIN_ONE 65535u  /* SET_STATE gain of the capped full drive */
#define RP_RATE_ONE 4096u   /* SET_STATE rate (Q12) that plays the pattern as stored */
#define RP_RATE_MIN 1024u
#define RP_RATE_MAX 16384u
#define RP_AMP_ONE 32767    /* Q15 full drive */
#define RP_MIN_FADE_MS 5u   /* every ramp lasts at least this long */
/* Longest pattern: the Q16 position of its end must fit 31 bits. */
#define RP_PLAYER_MAX_LENGTH 32768u

typedef struct {
    /* configuration */
    uint32_t sample_rate; /* Hz */
    int32_t gain_cap;     /* Q15, 0 … 32767: the drive at gain RP_GAIN_ONE */
    /* patterns */
    const int16_t *samples;
    uint32_t length;
    uint16_t id;
    const int16_t *next_samples;
    uint32_t next_length;
    uint16_t next_id;
    uint8_t has_next;
    uint32_t swaps; /* patterns swapped in so far */
    /* state */
    uint8_t playing;
    int32_t amp, amp0, amp_target;
    uint32_t amp_k, amp_n;
    int32_t rate, rate0, rate_target; /* Q12 */
    uint32_t rate_k, rate_n;
    uint32_t pos; /* Q16 samples */
} rp_player;

/* sample_rate in Hz (> 0); gain_cap Q15, clamped to 0 … 32767. Silent, no pattern. */
void rp_player_init(rp_player *p, uint32_t sample_rate, int32_t gain_cap);

/* Applies a SET_STATE: playing 0/1, gain 0 … 65535, rate_q12 RP_RATE_MIN … RP_RATE_MAX,
 * fade_ms ≥ 0. Returns 0, or -1 (nothing changed) when a value is out of range. */
int rp_player_set_state(rp_player *p, unsigned playing, uint16_t gain, uint16_t rate_q12,
                        uint16_t fade_ms);

/* Queues a pattern of length samples (1 … RP_PLAYER_MAX_LENGTH): it replaces the playing one at
 * its next wrap, or at once when the player is idle or has none. A pattern already waiting is
 * dropped for this one. Returns 0, or -1 for a bad length. */
int rp_player_load(rp_player *p, const int16_t *samples, uint32_t length, uint16_t id);

/* The pattern playing and the one waiting for the wrap (NULL if none). */
const int16_t *rp_player_active(const rp_player *p);
const int16_t *rp_player_next(const rp_player *p);

/* Renders n output samples (int16, the drive before the DAC) into out. */
void rp_player_render(rp_player *p, int16_t *out, size_t n);

/* The 12-bit DAC code of an output sample: 2048 + (sample >> 4), clipped to 0 … 4095. */
uint16_t rp_dac_code(int16_t sample);

/* Renders n samples straight to 12-bit DAC codes. */
void rp_player_render_dac(rp_player *p, uint16_t *codes, size_t n);

/* The player's int16 sample of a 12-bit DAC code of a C header export (realpen export …
 * --format c-header): 16 * (code - 2048) + 8, so that at full drive (amp 32767) the player
 * gives the code back exactly (the +8 puts the code in the middle of its 16-step bin). */
int16_t rp_sample_of_code(uint16_t code);

#ifdef __cplusplus
}
#endif

#endif /* REALPEN_PLAYER_H */
