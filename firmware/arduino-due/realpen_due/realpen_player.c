/* The RealPen pattern player in plain C99; see realpen_player.h and docs/protocol.md. */
#include "realpen_player.h"

/* floor(a / b) for b > 0, as Python's //, which the contract's formulas use; C's / truncates
 * towards zero, which differs for a negative a (a ramp down). */
static int64_t floor_div(int64_t a, int64_t b) {
    int64_t q = a / b;
    if ((a % b) != 0 && a < 0) {
        q--;
    }
    return q;
}

/* a >> s as Python does it (floor) whatever the compiler does with a negative a: right shifts
 * of negative values are implementation-defined in C99 (6.5.7). */
static int64_t floor_shift(int64_t a, unsigned s) {
    return a >= 0 ? a >> s : -((-a - 1) >> s) - 1;
}

void rp_player_init(rp_player *p, uint32_t sample_rate, int32_t gain_cap) {
    p->sample_rate = sample_rate ? sample_rate : 1u;
    p->gain_cap = gain_cap < 0 ? 0 : (gain_cap > RP_AMP_ONE ? RP_AMP_ONE : gain_cap);
    p->samples = NULL;
    p->length = 0;
    p->id = 0;
    p->next_samples = NULL;
    p->next_length = 0;
    p->next_id = 0;
    p->has_next = 0;
    p->swaps = 0;
    p->playing = 0;
    p->amp = p->amp0 = p->amp_target = 0;
    p->amp_k = p->amp_n = 0;
    p->rate = p->rate0 = p->rate_target = (int32_t)RP_RATE_ONE;
    p->rate_k = p->rate_n = 0;
    p->pos = 0;
}

int rp_player_set_state(rp_player *p, unsigned playing, uint16_t gain, uint16_t rate_q12,
                        uint16_t fade_ms) {
    uint32_t fade = fade_ms < RP_MIN_FADE_MS ? RP_MIN_FADE_MS : fade_ms;
    if (playing > 1u || rate_q12 < RP_RATE_MIN || rate_q12 > RP_RATE_MAX) {
        return -1;
    }
    p->playing = (uint8_t)playing;
    p->amp0 = p->amp;
    p->amp_target = playing ? (int32_t)(((uint32_t)gain * (uint32_t)p->gain_cap) / RP_GAIN_ONE)
                            : 0;
    p->amp_k = 0;
    /* At least one sample: below 200 Hz a 5 ms ramp would be shorter than a sample. */
    p->amp_n = (uint32_t)(((uint64_t)fade * p->sample_rate) / 1000u);
    if (p->amp_n == 0) {
        p->amp_n = 1;
    }
    if ((int32_t)rate_q12 != p->rate_target) {
        /* Only a change of rate starts a rate ramp: repeating a SET_STATE (as hosts do to
         * mend a lost frame) must not restart one that is under way. */
        p->rate0 = p->rate;
        p->rate_target = (int32_t)rate_q12;
        p->rate_k = 0;
        p->rate_n = (RP_MIN_FADE_MS * p->sample_rate) / 1000u;
        if (p->rate_n == 0) {
            p->rate_n = 1;
        }
    }
    return 0;
}

static void swap_in(rp_player *p) {
    p->samples = p->next_samples;
    p->length = p->next_length;
    p->id = p->next_id;
    p->next_samples = NULL;
    p->next_length = 0;
    p->has_next = 0;
    p->pos = 0;
    p->swaps++;
}

static int idle(const rp_player *p) { return !p->playing && p->amp == 0; }

int rp_player_load(rp_player *p, const int16_t *samples, uint32_t length, uint16_t id) {
    if (samples == NULL || length == 0 || length > RP_PLAYER_MAX_LENGTH) {
        return -1;
    }
    p->next_samples = samples;
    p->next_length = length;
    p->next_id = id;
    p->has_next = 1;
    if (p->samples == NULL || idle(p)) {
        swap_in(p);
    }
    return 0;
}

const int16_t *rp_player_active(const rp_player *p) { return p->samples; }

const int16_t *rp_player_next(const rp_player *p) { return p->has_next ? p->next_samples : NULL; }

/* The pattern at Q16 position pos: the sample itself at a whole position, else the straight
 * line to the next one (the loop's first sample after its last), with the fraction cut to
 * 14 bits as the MicroPython player does (there (b - a) * frac must fit a 31-bit small int):
 * a + floor((b - a) * (frac >> 2) / 2**14). */
static int32_t sample_at(const rp_player *p, uint32_t pos) {
    uint32_t i = pos >> 16, frac = pos & 0xFFFFu;
    int32_t a = p->samples[i], b;
    if (frac == 0) {
        return a;
    }
    b = p->samples[i + 1u < p->length ? i + 1u : 0u];
    return a + (int32_t)floor_shift((int64_t)(b - a) * (int64_t)(frac >> 2), 14);
}

void rp_player_render(rp_player *p, int16_t *out, size_t n) {
    size_t j;
    uint32_t end;
    for (j = 0; j < n; j++) {
        if (p->amp_k < p->amp_n) {
            p->amp_k++;
            p->amp = p->amp0 + (int32_t)floor_div((int64_t)(p->amp_target - p->amp0) * p->amp_k,
                                                  (int64_t)p->amp_n);
        }
        if (p->rate_k < p->rate_n) {
            p->rate_k++;
            p->rate = p->rate0 + (int32_t)floor_div(
                                     (int64_t)(p->rate_target - p->rate0) * p->rate_k,
                                     (int64_t)p->rate_n);
        }
        if (p->samples == NULL) {
            out[j] = 0;
            continue;
        }
        out[j] = (int16_t)floor_shift((int64_t)sample_at(p, p->pos) * p->amp, 15);
        if (idle(p)) {
            /* Silent and stopped: the next stroke starts at the pattern's start, with the
             * newest pattern. */
            p->pos = 0;
            if (p->has_next) {
                swap_in(p);
            }
            continue;
        }
        p->pos += (uint32_t)p->rate << 4;
        end = p->length << 16;
        if (p->pos >= end) {
            p->pos -= end;
            if (p->has_next) {
                swap_in(p); /* at the wrap, so the loop never clicks */
            } else if (p->pos >= end) {
                p->pos %= end; /* a pattern shorter than one step */
            }
        }
    }
}

uint16_t rp_dac_code(int16_t sample) {
    int32_t code = 2048 + (int32_t)floor_shift(sample, 4);
    return (uint16_t)(code < 0 ? 0 : (code > 4095 ? 4095 : code));
}

void rp_player_render_dac(rp_player *p, uint16_t *codes, size_t n) {
    int16_t block[32];
    size_t done = 0, k, m;
    while (done < n) {
        m = n - done < 32u ? n - done : 32u;
        rp_player_render(p, block, m);
        for (k = 0; k < m; k++) {
            codes[done + k] = rp_dac_code(block[k]);
        }
        done += m;
    }
}

int16_t rp_sample_of_code(uint16_t code) {
    int32_t c = code > 4095u ? 4095 : (int32_t)code;
    return (int16_t)(16 * (c - 2048) + 8);
}
