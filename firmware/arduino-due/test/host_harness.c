/* Host test harness for the Due's C protocol codec and player (tests/test_due.py builds it
 * with cc and drives it). Not part of the sketch: arduino-cli compiles only the sketch folder.
 *
 * Line commands on stdin, one answer line each on stdout (hex is lowercase, "-" = empty):
 *   crc16 HEX | crc32 HEX                 → the CRC in decimal
 *   cobs_enc HEX | cobs_dec HEX           → HEX, or "err"
 *   frame TYPE SEQ HEX                    → the wire frame HEX
 *   decode HEX                            → "FRAMES ERRORS [TYPE,SEQ,HEX …]"
 *   pack NAME ARGS…                       → payload HEX (info's name, chunk's and samples'
 *                                           data as HEX), or "err" for samples out of range
 *   unpack NAME HEX                       → the fields in decimal (data as HEX), or "err"
 *   pen RATE BUFFER_BYTES GAIN_CAP NAMEHEX → "ok": a fresh pen and player
 *   feed HEX                              → what the pen sent back, HEX
 *   poll UNDERRUNS                        → what the pen sent back, HEX
 *   state PLAYING GAIN RATE FADE          → set_state's return value
 *   load ID HEX                           → load's return value (samples s16le, harness memory)
 *   render N | dac N                      → N output samples | N DAC codes, decimal
 *   info                                  → "ACTIVE_ID SWAPS HAS_NEXT POS AMP"
 *   code C                                → rp_sample_of_code(C)
 * and one batch mode:
 *   host_harness fuzz STREAM_FILE OUT_FILE SEED
 *     feeds the stream to a pen in pseudo-random pieces, rendering a block after each,
 *     writes everything the pen sent to OUT_FILE and prints "DECODER_ERRORS BYTES_OUT".
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "realpen_player.h"
#include "realpen_protocol.h"

#define LINE_MAX_BYTES (4u << 20)
#define OUT_MAX (1u << 16)
#define LOAD_SLOTS 8
#define LOAD_SAMPLES 65536u

static char line[LINE_MAX_BYTES];
static uint8_t bytes[LINE_MAX_BYTES / 2];
static uint8_t scratch[LINE_MAX_BYTES / 2];
static uint8_t out_buf[OUT_MAX];
static size_t out_n;

static rp_player player;
static rp_pen pen;
static int16_t pen_memory[RP_PEN_BUFFERS][LOAD_SAMPLES];
static int16_t load_memory[LOAD_SLOTS][LOAD_SAMPLES];
static int load_next;
static uint32_t fake_clock;
static char pen_name[RP_MAX_NAME + 1];

static void collect(void *ctx, const uint8_t *data, size_t n) {
    (void)ctx;
    if (out_n + n <= OUT_MAX) {
        memcpy(out_buf + out_n, data, n);
        out_n += n;
    } else {
        fprintf(stderr, "harness: pen output overflow\n");
        exit(3);
    }
}

static uint32_t clock_us(void *ctx) {
    (void)ctx;
    return fake_clock += 1000u;
}

/* The sketch masks interrupts here; the harness checks that every enter has its leave and
 * that they never nest (a nested pair would unmask interrupts too early on the Due). */
static int guard_depth;
static void guard(void *ctx, int enter) {
    (void)ctx;
    if (enter ? guard_depth != 0 : guard_depth != 1) {
        fprintf(stderr, "harness: unbalanced guard\n");
        exit(4);
    }
    guard_depth = enter ? 1 : 0;
}

static int hexval(int c) {
    if (c >= '0' && c <= '9') {
        return c - '0';
    }
    if (c >= 'a' && c <= 'f') {
        return c - 'a' + 10;
    }
    if (c >= 'A' && c <= 'F') {
        return c - 'A' + 10;
    }
    return -1;
}

/* Parses a hex token ("-" or NULL = empty) into out; returns the byte count. */
static size_t unhex(const char *s, uint8_t *out) {
    size_t n = 0;
    if (s == NULL || strcmp(s, "-") == 0) {
        return 0;
    }
    while (s[0] && s[1]) {
        int hi = hexval(s[0]), lo = hexval(s[1]);
        if (hi < 0 || lo < 0) {
            fprintf(stderr, "harness: bad hex\n");
            exit(2);
        }
        out[n++] = (uint8_t)(hi * 16 + lo);
        s += 2;
    }
    return n;
}

static void print_hex(const uint8_t *data, size_t n) {
    size_t i;
    if (n == 0) {
        fputs("-", stdout);
    }
    for (i = 0; i < n; i++) {
        printf("%02x", data[i]);
    }
}

static unsigned long arg(char **tok, int i) { return tok[i] ? strtoul(tok[i], NULL, 0) : 0ul; }

static void pen_setup(uint32_t rate, uint32_t buffer_bytes, int32_t gain_cap, const char *name) {
    int16_t *buffers[RP_PEN_BUFFERS];
    rp_info info;
    int i;
    for (i = 0; i < RP_PEN_BUFFERS; i++) {
        buffers[i] = pen_memory[i];
    }
    if (buffer_bytes > LOAD_SAMPLES * 2u) {
        buffer_bytes = LOAD_SAMPLES * 2u;
    }
    info.protocol = RP_PROTOCOL_VERSION;
    info.fw_major = 0;
    info.fw_minor = 1;
    info.fw_patch = 0;
    info.sample_rate = rate;
    info.max_pattern_bytes = buffer_bytes;
    info.features = RP_FEATURE_USB | RP_FEATURE_RATE;
    info.name = name;
    rp_player_init(&player, rate, gain_cap);
    rp_pen_init(&pen, &player, buffers, buffer_bytes, &info, collect, clock_us, NULL);
    pen.guard = guard;
    fake_clock = 0;
}

static void print_samples(size_t n, int dac) {
    static int16_t s[LOAD_SAMPLES];
    static uint16_t c[LOAD_SAMPLES];
    size_t i;
    if (n > LOAD_SAMPLES) {
        n = LOAD_SAMPLES;
    }
    if (dac) {
        rp_player_render_dac(&player, c, n);
    } else {
        rp_player_render(&player, s, n);
    }
    for (i = 0; i < n; i++) {
        printf(i ? " %d" : "%d", dac ? (int)c[i] : (int)s[i]);
    }
}

static void do_pack(char **tok) {
    uint8_t p[RP_MAX_FRAME];
    size_t n = 0, m;
    const char *name = tok[1] ? tok[1] : "";
    if (strcmp(name, "pack_hello") == 0) {
        n = rp_pack_hello(p, (uint16_t)arg(tok, 2));
    } else if (strcmp(name, "pack_info") == 0) {
        rp_info info;
        static char nm[RP_MAX_NAME * 2 + 1];
        m = unhex(tok[9], scratch);
        if (m > sizeof nm - 1) {
            m = sizeof nm - 1;
        }
        memcpy(nm, scratch, m);
        nm[m] = 0;
        info.protocol = (uint16_t)arg(tok, 2);
        info.fw_major = (uint8_t)arg(tok, 3);
        info.fw_minor = (uint8_t)arg(tok, 4);
        info.fw_patch = (uint8_t)arg(tok, 5);
        info.sample_rate = (uint32_t)arg(tok, 6);
        info.max_pattern_bytes = (uint32_t)arg(tok, 7);
        info.features = (uint32_t)arg(tok, 8);
        info.name = nm;
        n = rp_pack_info(p, &info);
    } else if (strcmp(name, "pack_pattern_begin") == 0) {
        rp_begin b;
        b.id = (uint16_t)arg(tok, 2);
        b.length = (uint32_t)arg(tok, 3);
        b.rate = (uint32_t)arg(tok, 4);
        b.format = (uint8_t)arg(tok, 5);
        b.crc32 = (uint32_t)arg(tok, 6);
        n = rp_pack_begin(p, &b);
    } else if (strcmp(name, "pack_pattern_chunk") == 0) {
        m = unhex(tok[3], scratch);
        n = rp_pack_chunk(p, (uint32_t)arg(tok, 2), scratch, m);
    } else if (strcmp(name, "pack_pattern_commit") == 0) {
        n = rp_pack_commit(p, (uint16_t)arg(tok, 2));
    } else if (strcmp(name, "pack_set_state") == 0) {
        rp_state s;
        s.playing = (uint8_t)arg(tok, 2);
        s.gain = (uint16_t)arg(tok, 3);
        s.rate = (uint16_t)arg(tok, 4);
        s.fade_ms = (uint16_t)arg(tok, 5);
        n = rp_pack_state(p, &s);
    } else if (strcmp(name, "pack_ping") == 0) {
        n = rp_pack_ping(p, (uint32_t)arg(tok, 2));
    } else if (strcmp(name, "pack_pong") == 0) {
        n = rp_pack_pong(p, (uint32_t)arg(tok, 2), (uint32_t)arg(tok, 3));
    } else if (strcmp(name, "pack_ack") == 0) {
        n = rp_pack_ack(p, (uint8_t)arg(tok, 2));
    } else if (strcmp(name, "pack_nack") == 0) {
        n = rp_pack_nack(p, (uint8_t)arg(tok, 2), (uint8_t)arg(tok, 3));
    } else if (strcmp(name, "pack_event") == 0) {
        n = rp_pack_event(p, (uint8_t)arg(tok, 2), (uint32_t)arg(tok, 3));
    } else if (strcmp(name, "pack_capture_start") == 0) {
        n = rp_pack_capture_start(p, (uint8_t)arg(tok, 2), (uint16_t)arg(tok, 3));
    } else if (strcmp(name, "pack_capture_stop") == 0) {
        n = 0; /* no payload */
    } else if (strcmp(name, "pack_samples") == 0) {
        rp_samples s;
        s.first = (uint32_t)arg(tok, 2);
        s.t_us = (uint32_t)arg(tok, 3);
        s.range_g = (uint8_t)arg(tok, 4);
        s.flags = (uint8_t)arg(tok, 5);
        m = unhex(tok[6], scratch);
        n = rp_pack_samples(p, &s, scratch, m);
        if (n == 0) {
            fputs("err", stdout);
            return;
        }
    } else {
        fputs("unknown", stdout);
        return;
    }
    print_hex(p, n);
}

static void do_unpack(char **tok) {
    const char *name = tok[1] ? tok[1] : "";
    size_t n = unhex(tok[2], bytes);
    int rc = -1;
    if (strcmp(name, "info") == 0) {
        rp_info i;
        const uint8_t *nm;
        size_t nn;
        rc = rp_unpack_info(bytes, n, &i, &nm, &nn);
        if (rc == 0) {
            printf("%u %u %u %u %lu %lu %lu ", i.protocol, i.fw_major, i.fw_minor, i.fw_patch,
                   (unsigned long)i.sample_rate, (unsigned long)i.max_pattern_bytes,
                   (unsigned long)i.features);
            print_hex(nm, nn);
        }
    } else if (strcmp(name, "begin") == 0) {
        rp_begin b;
        rc = rp_unpack_begin(bytes, n, &b);
        if (rc == 0) {
            printf("%u %lu %lu %u %lu", b.id, (unsigned long)b.length, (unsigned long)b.rate,
                   b.format, (unsigned long)b.crc32);
        }
    } else if (strcmp(name, "chunk") == 0) {
        uint32_t off;
        const uint8_t *d;
        size_t dn;
        rc = rp_unpack_chunk(bytes, n, &off, &d, &dn);
        if (rc == 0) {
            printf("%lu ", (unsigned long)off);
            print_hex(d, dn);
        }
    } else if (strcmp(name, "state") == 0) {
        rp_state s;
        rc = rp_unpack_state(bytes, n, &s);
        if (rc == 0) {
            printf("%u %u %u %u", s.playing, s.gain, s.rate, s.fade_ms);
        }
    } else if (strcmp(name, "pong") == 0) {
        uint32_t t, us;
        rc = rp_unpack_pong(bytes, n, &t, &us);
        if (rc == 0) {
            printf("%lu %lu", (unsigned long)t, (unsigned long)us);
        }
    } else if (strcmp(name, "nack") == 0) {
        uint8_t t, c;
        rc = rp_unpack_nack(bytes, n, &t, &c);
        if (rc == 0) {
            printf("%u %u", t, c);
        }
    } else if (strcmp(name, "event") == 0) {
        uint8_t k;
        uint32_t v;
        rc = rp_unpack_event(bytes, n, &k, &v);
        if (rc == 0) {
            printf("%u %lu", k, (unsigned long)v);
        }
    } else if (strcmp(name, "capture_start") == 0) {
        uint8_t range_g;
        uint16_t rate_hz;
        rc = rp_unpack_capture_start(bytes, n, &range_g, &rate_hz);
        if (rc == 0) {
            printf("%u %u", range_g, rate_hz);
        }
    } else if (strcmp(name, "capture_stop") == 0) {
        rc = rp_unpack_capture_stop(bytes, n);
        if (rc == 0) {
            fputs("-", stdout);
        }
    } else if (strcmp(name, "samples") == 0) {
        rp_samples s;
        const uint8_t *d;
        size_t dn;
        rc = rp_unpack_samples(bytes, n, &s, &d, &dn);
        if (rc == 0) {
            printf("%lu %lu %u %u ", (unsigned long)s.first, (unsigned long)s.t_us, s.range_g,
                   s.flags);
            print_hex(d, dn);
        }
    } else {
        uint16_t v16;
        uint32_t v32;
        uint8_t v8;
        if (strcmp(name, "hello") == 0 && (rc = rp_unpack_hello(bytes, n, &v16)) == 0) {
            printf("%u", v16);
        } else if (strcmp(name, "commit") == 0 && (rc = rp_unpack_commit(bytes, n, &v16)) == 0) {
            printf("%u", v16);
        } else if (strcmp(name, "ping") == 0 && (rc = rp_unpack_ping(bytes, n, &v32)) == 0) {
            printf("%lu", (unsigned long)v32);
        } else if (strcmp(name, "ack") == 0 && (rc = rp_unpack_ack(bytes, n, &v8)) == 0) {
            printf("%u", v8);
        }
    }
    if (rc != 0) {
        fputs("err", stdout);
    }
}

static void do_decode(const char *hex) {
    static rp_decoder d;
    static char frames[LINE_MAX_BYTES];
    size_t n = unhex(hex, bytes), i, used = 0, count = 0, k;
    rp_frame f;
    rp_decoder_init(&d);
    frames[0] = 0;
    for (i = 0; i < n; i++) {
        if (rp_decoder_push(&d, bytes[i], &f)) {
            count++;
            used += (size_t)sprintf(frames + used, " %u,%u,", f.type, f.seq);
            for (k = 0; k < f.length; k++) {
                used += (size_t)sprintf(frames + used, "%02x", f.payload[k]);
            }
        }
    }
    printf("%lu %lu%s", (unsigned long)count, (unsigned long)d.errors, frames);
}

static int command(char *text) {
    char *tok[16] = {0};
    int nt = 0;
    char *t = strtok(text, " \t\r\n");
    const char *c;
    size_t n, m, i;
    while (t && nt < 16) {
        tok[nt++] = t;
        t = strtok(NULL, " \t\r\n");
    }
    if (nt == 0) {
        return 0;
    }
    c = tok[0];
    out_n = 0;
    if (strcmp(c, "crc16") == 0) {
        n = unhex(tok[1], bytes);
        printf("%u", rp_crc16(bytes, n, 0xFFFFu));
    } else if (strcmp(c, "crc32") == 0) {
        n = unhex(tok[1], bytes);
        printf("%lu", (unsigned long)rp_crc32(bytes, n, 0));
    } else if (strcmp(c, "cobs_enc") == 0) {
        n = unhex(tok[1], bytes);
        m = rp_cobs_encode(bytes, n, scratch, n + n / 254u + 1u);
        if (m == 0) {
            fputs("err", stdout);
        } else {
            print_hex(scratch, m);
        }
    } else if (strcmp(c, "cobs_dec") == 0) {
        n = unhex(tok[1], bytes);
        if (rp_cobs_decode(bytes, n, scratch, sizeof scratch, &m) != 0) {
            fputs("err", stdout);
        } else {
            print_hex(scratch, m);
        }
    } else if (strcmp(c, "frame") == 0) {
        n = unhex(tok[3], bytes);
        m = rp_encode_frame((uint8_t)arg(tok, 1), (uint8_t)arg(tok, 2), bytes, n, scratch,
                            RP_MAX_WIRE);
        if (m == 0) {
            fputs("err", stdout);
        } else {
            print_hex(scratch, m);
        }
    } else if (strcmp(c, "decode") == 0) {
        do_decode(tok[1]);
    } else if (strcmp(c, "pack") == 0) {
        do_pack(tok);
    } else if (strcmp(c, "unpack") == 0) {
        do_unpack(tok);
    } else if (strcmp(c, "pen") == 0) {
        n = unhex(tok[4], bytes);
        if (n > RP_MAX_NAME) {
            n = RP_MAX_NAME;
        }
        memcpy(pen_name, bytes, n);
        pen_name[n] = 0;
        pen_setup((uint32_t)arg(tok, 1), (uint32_t)arg(tok, 2), (int32_t)arg(tok, 3), pen_name);
        fputs("ok", stdout);
    } else if (strcmp(c, "feed") == 0) {
        n = unhex(tok[1], bytes);
        rp_pen_feed(&pen, bytes, n);
        print_hex(out_buf, out_n);
    } else if (strcmp(c, "poll") == 0) {
        rp_pen_poll(&pen, (uint32_t)arg(tok, 1));
        print_hex(out_buf, out_n);
    } else if (strcmp(c, "state") == 0) {
        printf("%d", rp_player_set_state(&player, (unsigned)arg(tok, 1), (uint16_t)arg(tok, 2),
                                         (uint16_t)arg(tok, 3), (uint16_t)arg(tok, 4)));
    } else if (strcmp(c, "load") == 0) {
        int16_t *slot = load_memory[load_next];
        load_next = (load_next + 1) % LOAD_SLOTS;
        n = unhex(tok[2], bytes) / 2u;
        if (n > LOAD_SAMPLES) {
            n = LOAD_SAMPLES;
        }
        for (i = 0; i < n; i++) {
            int32_t v = (int32_t)(bytes[2 * i] | (bytes[2 * i + 1] << 8));
            slot[i] = (int16_t)(v >= 0x8000 ? v - 0x10000 : v);
        }
        printf("%d", rp_player_load(&player, slot, (uint32_t)n, (uint16_t)arg(tok, 1)));
    } else if (strcmp(c, "render") == 0 || strcmp(c, "dac") == 0) {
        print_samples((size_t)arg(tok, 1), c[0] == 'd');
    } else if (strcmp(c, "info") == 0) {
        printf("%u %lu %u %lu %ld", player.id, (unsigned long)player.swaps, player.has_next,
               (unsigned long)player.pos, (long)player.amp);
    } else if (strcmp(c, "code") == 0) {
        printf("%d", rp_sample_of_code((uint16_t)arg(tok, 1)));
    } else {
        fputs("unknown", stdout);
    }
    fputc('\n', stdout);
    fflush(stdout);
    return 0;
}

/* xorshift32: the piece sizes of the fuzz feed, reproducible from the seed. */
static uint32_t rng_state = 2463534242u;
static uint32_t rng(void) {
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 17;
    rng_state ^= rng_state << 5;
    return rng_state;
}

static int fuzz(const char *in_path, const char *out_path, unsigned long seed) {
    FILE *in = fopen(in_path, "rb"), *out;
    static uint8_t stream[32u << 20];
    static int16_t block[16];
    size_t n, at = 0, piece, total_out = 0;
    if (!in) {
        perror(in_path);
        return 2;
    }
    n = fread(stream, 1, sizeof stream, in);
    fclose(in);
    out = fopen(out_path, "wb");
    if (!out) {
        perror(out_path);
        return 2;
    }
    rng_state = (uint32_t)seed | 1u;
    pen_setup(8000u, 4096u, RP_AMP_ONE, "fuzz");
    while (at < n) {
        piece = 1u + rng() % 64u;
        if (piece > n - at) {
            piece = n - at;
        }
        out_n = 0;
        rp_pen_feed(&pen, stream + at, piece);
        at += piece;
        rp_player_render(&player, block, 16);
        rp_pen_poll(&pen, 0);
        fwrite(out_buf, 1, out_n, out);
        total_out += out_n;
    }
    fclose(out);
    printf("%lu %lu\n", (unsigned long)pen.decoder.errors, (unsigned long)total_out);
    return 0;
}

int main(int argc, char **argv) {
    if (argc >= 5 && strcmp(argv[1], "fuzz") == 0) {
        return fuzz(argv[2], argv[3], strtoul(argv[4], NULL, 0));
    }
    pen_setup(8000u, 32768u, RP_AMP_ONE, "harness");
    while (fgets(line, sizeof line, stdin)) {
        command(line);
    }
    return 0;
}
