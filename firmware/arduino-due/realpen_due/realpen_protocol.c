/* The RealPen pen protocol in plain C99; see realpen_protocol.h and docs/protocol.md. */
#include "realpen_protocol.h"

#include <string.h>

/* --- little-endian fields -------------------------------------------------------------- */

static void put16(uint8_t *p, uint16_t v) {
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

static void put32(uint8_t *p, uint32_t v) {
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)((v >> 8) & 0xFFu);
    p[2] = (uint8_t)((v >> 16) & 0xFFu);
    p[3] = (uint8_t)(v >> 24);
}

static uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | ((uint16_t)p[1] << 8)); }

static uint32_t get32(const uint8_t *p) {
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) |
           ((uint32_t)p[3] << 24);
}

/* --- checksums ------------------------------------------------------------------------- */

uint16_t rp_crc16(const uint8_t *data, size_t n, uint16_t crc) {
    /* Bitwise rather than a 512-byte table: frames are short and flash is better spent on
     * the pattern; a 256-byte frame costs about 2k shift/XOR steps. */
    size_t i;
    int bit;
    uint32_t c = crc;
    for (i = 0; i < n; i++) {
        c ^= (uint32_t)data[i] << 8;
        for (bit = 0; bit < 8; bit++) {
            c = (c & 0x8000u) ? ((c << 1) ^ 0x1021u) : (c << 1);
        }
        c &= 0xFFFFu;
    }
    return (uint16_t)c;
}

uint32_t rp_crc32(const uint8_t *data, size_t n, uint32_t crc) {
    /* Half-byte table (64 bytes of flash): the reflected IEEE polynomial 0xEDB88320. */
    static const uint32_t table[16] = {
        0x00000000u, 0x1DB71064u, 0x3B6E20C8u, 0x26D930ACu, 0x76DC4190u, 0x6B6B51F4u,
        0x4DB26158u, 0x5005713Cu, 0xEDB88320u, 0xF00F9344u, 0xD6D6A3E8u, 0xCB61B38Cu,
        0x9B64C2B0u, 0x86D3D2D4u, 0xA00AE278u, 0xBDBDF21Cu};
    size_t i;
    crc = ~crc;
    for (i = 0; i < n; i++) {
        crc ^= data[i];
        crc = (crc >> 4) ^ table[crc & 0x0Fu];
        crc = (crc >> 4) ^ table[crc & 0x0Fu];
    }
    return ~crc;
}

/* --- COBS ------------------------------------------------------------------------------ */

size_t rp_cobs_encode(const uint8_t *in, size_t n, uint8_t *out, size_t cap) {
    size_t o = 1, code_at = 0, i;
    uint8_t code = 1;
    int after_full_block = 0; /* a block of 254 data bytes ended just before the current one */
    if (cap < 1) {
        return 0;
    }
    for (i = 0; i < n; i++) {
        after_full_block = 0;
        if (in[i] == 0) {
            out[code_at] = code;
            if (o >= cap) {
                return 0;
            }
            code_at = o++;
            code = 1;
        } else {
            if (o >= cap) {
                return 0;
            }
            out[o++] = in[i];
            code++;
            if (code == 0xFF) {
                out[code_at] = code;
                if (o >= cap) {
                    return 0;
                }
                code_at = o++;
                code = 1;
                after_full_block = 1;
            }
        }
    }
    if (after_full_block) {
        return code_at; /* data ending exactly at a full block needs no empty block after it */
    }
    out[code_at] = code;
    return o;
}

int rp_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_n) {
    size_t index = 0, o = 0, stop, at;
    uint8_t code;
    while (index < n) {
        code = in[index];
        if (code == 0) {
            return -1;
        }
        index++;
        stop = index + code - 1u;
        if (stop > n) {
            return -1;
        }
        for (at = index; at < stop; at++) {
            if (in[at] == 0) {
                return -1;
            }
            if (o >= cap) {
                return -2;
            }
            out[o++] = in[at];
        }
        index = stop;
        if (code != 0xFF && index < n) {
            if (o >= cap) {
                return -2;
            }
            out[o++] = 0;
        }
    }
    *out_n = o;
    return 0;
}

/* --- frames ---------------------------------------------------------------------------- */

size_t rp_encode_frame(uint8_t type, uint8_t seq, const uint8_t *payload, size_t n,
                       uint8_t *out, size_t cap) {
    uint8_t body[RP_MAX_FRAME];
    size_t size = n + 4u, encoded;
    uint16_t crc;
    if (n > RP_MAX_FRAME - 4u) {
        return 0;
    }
    body[0] = type;
    body[1] = seq;
    if (n) {
        memcpy(body + 2, payload, n);
    }
    crc = rp_crc16(body, n + 2u, 0xFFFFu);
    put16(body + n + 2u, crc);
    if (cap < 2) {
        return 0;
    }
    encoded = rp_cobs_encode(body, size, out, cap - 1u);
    if (encoded == 0) {
        return 0;
    }
    out[encoded] = 0;
    return encoded + 1u;
}

void rp_decoder_init(rp_decoder *d) {
    d->length = 0;
    d->overflow = 0;
    d->errors = 0;
}

int rp_decoder_push(rp_decoder *d, uint8_t byte, rp_frame *frame) {
    size_t n;
    int good = 0;
    if (byte != 0) {
        if (!d->overflow) {
            if (d->length >= RP_MAX_ENCODED) {
                /* Too long to be a frame: drop it and skip to the next delimiter. */
                d->overflow = 1;
                d->length = 0;
            } else {
                d->encoded[d->length++] = byte;
            }
        }
        return 0;
    }
    if (d->overflow) {
        d->errors++;
    } else if (d->length) {
        if (rp_cobs_decode(d->encoded, d->length, d->body, RP_MAX_FRAME, &n) != 0 || n < 4u ||
            rp_crc16(d->body, n - 2u, 0xFFFFu) != get16(d->body + n - 2u)) {
            d->errors++;
        } else {
            frame->type = d->body[0];
            frame->seq = d->body[1];
            frame->payload = d->body + 2;
            frame->length = n - 4u;
            good = 1;
        }
    }
    d->overflow = 0;
    d->length = 0;
    return good;
}

/* --- message structs ------------------------------------------------------------------- */

size_t rp_pack_hello(uint8_t *out, uint16_t version) {
    put16(out, version);
    return RP_HELLO_SIZE;
}

int rp_unpack_hello(const uint8_t *p, size_t n, uint16_t *version) {
    if (n != RP_HELLO_SIZE) {
        return -1;
    }
    *version = get16(p);
    return 0;
}

/* Bytes of name to send: at most RP_MAX_NAME, never cutting a UTF-8 sequence. */
static size_t name_bytes(const char *name) {
    size_t n = name ? strlen(name) : 0;
    if (n > RP_MAX_NAME) {
        n = RP_MAX_NAME;
        while (n > 0 && (((const uint8_t *)name)[n] & 0xC0u) == 0x80u) {
            n--;
        }
    }
    return n;
}

size_t rp_pack_info(uint8_t *out, const rp_info *info) {
    size_t name_n = name_bytes(info->name);
    put16(out, info->protocol);
    out[2] = info->fw_major;
    out[3] = info->fw_minor;
    out[4] = info->fw_patch;
    put32(out + 5, info->sample_rate);
    put32(out + 9, info->max_pattern_bytes);
    put32(out + 13, info->features);
    if (name_n) {
        memcpy(out + RP_INFO_SIZE, info->name, name_n);
    }
    return RP_INFO_SIZE + name_n;
}

int rp_unpack_info(const uint8_t *p, size_t n, rp_info *info, const uint8_t **name_out,
                   size_t *name_n) {
    if (n < RP_INFO_SIZE || n > RP_INFO_SIZE + RP_MAX_NAME) {
        return -1;
    }
    info->protocol = get16(p);
    info->fw_major = p[2];
    info->fw_minor = p[3];
    info->fw_patch = p[4];
    info->sample_rate = get32(p + 5);
    info->max_pattern_bytes = get32(p + 9);
    info->features = get32(p + 13);
    info->name = NULL;
    *name_out = p + RP_INFO_SIZE;
    *name_n = n - RP_INFO_SIZE;
    return 0;
}

size_t rp_pack_begin(uint8_t *out, const rp_begin *b) {
    put16(out, b->id);
    put32(out + 2, b->length);
    put32(out + 6, b->rate);
    out[10] = b->format;
    put32(out + 11, b->crc32);
    return RP_BEGIN_SIZE;
}

int rp_unpack_begin(const uint8_t *p, size_t n, rp_begin *b) {
    if (n != RP_BEGIN_SIZE) {
        return -1;
    }
    b->id = get16(p);
    b->length = get32(p + 2);
    b->rate = get32(p + 6);
    b->format = p[10];
    b->crc32 = get32(p + 11);
    return 0;
}

size_t rp_pack_chunk(uint8_t *out, uint32_t offset, const uint8_t *data, size_t n) {
    if (n > RP_MAX_CHUNK) {
        n = RP_MAX_CHUNK;
    }
    put32(out, offset);
    if (n) {
        memcpy(out + RP_CHUNK_HEAD, data, n);
    }
    return RP_CHUNK_HEAD + n;
}

int rp_unpack_chunk(const uint8_t *p, size_t n, uint32_t *offset, const uint8_t **data,
                    size_t *data_n) {
    if (n < RP_CHUNK_HEAD + 1u || n > RP_CHUNK_HEAD + RP_MAX_CHUNK) {
        return -1;
    }
    *offset = get32(p);
    *data = p + RP_CHUNK_HEAD;
    *data_n = n - RP_CHUNK_HEAD;
    return 0;
}

size_t rp_pack_commit(uint8_t *out, uint16_t id) {
    put16(out, id);
    return RP_COMMIT_SIZE;
}

int rp_unpack_commit(const uint8_t *p, size_t n, uint16_t *id) {
    if (n != RP_COMMIT_SIZE) {
        return -1;
    }
    *id = get16(p);
    return 0;
}

size_t rp_pack_state(uint8_t *out, const rp_state *s) {
    out[0] = s->playing;
    put16(out + 1, s->gain);
    put16(out + 3, s->rate);
    put16(out + 5, s->fade_ms);
    return RP_STATE_SIZE;
}

int rp_unpack_state(const uint8_t *p, size_t n, rp_state *s) {
    if (n != RP_STATE_SIZE) {
        return -1;
    }
    s->playing = p[0];
    s->gain = get16(p + 1);
    s->rate = get16(p + 3);
    s->fade_ms = get16(p + 5);
    return 0;
}

size_t rp_pack_ping(uint8_t *out, uint32_t token) {
    put32(out, token);
    return RP_PING_SIZE;
}

int rp_unpack_ping(const uint8_t *p, size_t n, uint32_t *token) {
    if (n != RP_PING_SIZE) {
        return -1;
    }
    *token = get32(p);
    return 0;
}

size_t rp_pack_pong(uint8_t *out, uint32_t token, uint32_t device_us) {
    put32(out, token);
    put32(out + 4, device_us);
    return RP_PONG_SIZE;
}

int rp_unpack_pong(const uint8_t *p, size_t n, uint32_t *token, uint32_t *device_us) {
    if (n != RP_PONG_SIZE) {
        return -1;
    }
    *token = get32(p);
    *device_us = get32(p + 4);
    return 0;
}

size_t rp_pack_ack(uint8_t *out, uint8_t type) {
    out[0] = type;
    return RP_ACK_SIZE;
}

int rp_unpack_ack(const uint8_t *p, size_t n, uint8_t *type) {
    if (n != RP_ACK_SIZE) {
        return -1;
    }
    *type = p[0];
    return 0;
}

size_t rp_pack_nack(uint8_t *out, uint8_t type, uint8_t code) {
    out[0] = type;
    out[1] = code;
    return RP_NACK_SIZE;
}

int rp_unpack_nack(const uint8_t *p, size_t n, uint8_t *type, uint8_t *code) {
    if (n != RP_NACK_SIZE) {
        return -1;
    }
    *type = p[0];
    *code = p[1];
    return 0;
}

size_t rp_pack_event(uint8_t *out, uint8_t kind, uint32_t value) {
    out[0] = kind;
    put32(out + 1, value);
    return RP_EVENT_SIZE;
}

int rp_unpack_event(const uint8_t *p, size_t n, uint8_t *kind, uint32_t *value) {
    if (n != RP_EVENT_SIZE) {
        return -1;
    }
    *kind = p[0];
    *value = get32(p + 1);
    return 0;
}

size_t rp_pack_capture_start(uint8_t *out, uint8_t range_g, uint16_t rate_hz) {
    out[0] = range_g;
    put16(out + 1, rate_hz);
    return RP_CAPTURE_START_SIZE;
}

int rp_unpack_capture_start(const uint8_t *p, size_t n, uint8_t *range_g, uint16_t *rate_hz) {
    if (n != RP_CAPTURE_START_SIZE) {
        return -1;
    }
    *range_g = p[0];
    *rate_hz = get16(p + 1);
    return 0;
}

int rp_unpack_capture_stop(const uint8_t *p, size_t n) {
    (void)p;
    return n == 0 ? 0 : -1;
}

static int samples_bytes_ok(size_t n) {
    return n > 0 && n % RP_SAMPLE_BYTES == 0 && n <= RP_MAX_BLOCK_SAMPLES * RP_SAMPLE_BYTES;
}

size_t rp_pack_samples(uint8_t *out, const rp_samples *s, const uint8_t *data, size_t n) {
    if (!samples_bytes_ok(n)) {
        return 0;
    }
    put32(out, s->first);
    put32(out + 4, s->t_us);
    out[8] = s->range_g;
    out[9] = s->flags;
    memcpy(out + RP_SAMPLES_HEAD, data, n);
    return RP_SAMPLES_HEAD + n;
}

int rp_unpack_samples(const uint8_t *p, size_t n, rp_samples *s, const uint8_t **data,
                      size_t *data_n) {
    if (n < RP_SAMPLES_HEAD || !samples_bytes_ok(n - RP_SAMPLES_HEAD)) {
        return -1;
    }
    s->first = get32(p);
    s->t_us = get32(p + 4);
    s->range_g = p[8];
    s->flags = p[9];
    *data = p + RP_SAMPLES_HEAD;
    *data_n = n - RP_SAMPLES_HEAD;
    return 0;
}

/* --- the pen --------------------------------------------------------------------------- */

static void send(rp_pen *pen, uint8_t type, uint8_t seq, const uint8_t *payload, size_t n) {
    uint8_t wire[RP_MAX_WIRE];
    size_t size = rp_encode_frame(type, seq, payload, n, wire, sizeof wire);
    if (size) {
        pen->write(pen->ctx, wire, size);
    }
}

static void enter(rp_pen *pen) {
    if (pen->guard) {
        pen->guard(pen->ctx, 1);
    }
}

static void leave(rp_pen *pen) {
    if (pen->guard) {
        pen->guard(pen->ctx, 0);
    }
}

static void ack(rp_pen *pen, const rp_frame *f) {
    uint8_t p[RP_ACK_SIZE];
    send(pen, RP_ACK, f->seq, p, rp_pack_ack(p, f->type));
}

static void nack(rp_pen *pen, const rp_frame *f, uint8_t code) {
    uint8_t p[RP_NACK_SIZE];
    send(pen, RP_NACK, f->seq, p, rp_pack_nack(p, f->type, code));
}

void rp_pen_init(rp_pen *pen, rp_player *player, int16_t *const buffers[RP_PEN_BUFFERS],
                 uint32_t buffer_bytes, const rp_info *info, rp_write_fn write,
                 rp_clock_fn clock, void *ctx) {
    int i;
    rp_decoder_init(&pen->decoder);
    pen->player = player;
    for (i = 0; i < RP_PEN_BUFFERS; i++) {
        pen->buffers[i] = buffers[i];
    }
    pen->buffer_bytes = buffer_bytes & ~1u;
    pen->info = *info;
    pen->info.max_pattern_bytes = pen->buffer_bytes;
    pen->write = write;
    pen->clock = clock;
    pen->guard = NULL;
    pen->ctx = ctx;
    pen->uploading = 0;
    pen->staging = NULL;
    pen->received = 0;
    pen->crc = 0;
    pen->event_seq = 0;
    pen->reported_swaps = player->swaps;
    pen->reported_errors = 0;
    pen->reported_underruns = 0;
}

/* A buffer the player is neither playing nor holding for its next wrap (there are three, the
 * player holds at most two). */
static int16_t *free_buffer(rp_pen *pen) {
    int i;
    const int16_t *a, *b;
    int16_t *found = NULL;
    enter(pen); /* both pointers from one instant: a swap in between could hide the playing one */
    a = rp_player_active(pen->player);
    b = rp_player_next(pen->player);
    leave(pen);
    for (i = 0; i < RP_PEN_BUFFERS && found == NULL; i++) {
        if (pen->buffers[i] != a && pen->buffers[i] != b) {
            found = pen->buffers[i];
        }
    }
    return found;
}

/* Stores one byte of the little-endian sample stream; byte by byte so that it is right on any
 * host, whatever its endianness, and whatever the chunk's parity. */
static void store_byte(int16_t *samples, uint32_t offset, uint8_t byte) {
    uint32_t i = offset >> 1;
    uint32_t u = (uint16_t)samples[i];
    int32_t v;
    if (offset & 1u) {
        u = (u & 0x00FFu) | ((uint32_t)byte << 8);
    } else {
        u = (u & 0xFF00u) | byte;
    }
    v = (int32_t)u;
    samples[i] = (int16_t)(v >= 0x8000 ? v - 0x10000 : v);
}

static void handle_begin(rp_pen *pen, const rp_frame *f) {
    rp_begin b;
    if (rp_unpack_begin(f->payload, f->length, &b) != 0) {
        nack(pen, f, RP_E_BAD_LENGTH);
        return;
    }
    pen->uploading = 0; /* a new BEGIN abandons any upload under way, refused or not */
    if (b.format != RP_FORMAT_S16LE || b.length == 0) {
        nack(pen, f, RP_E_BAD_FORMAT); /* as the Pico firmware: an empty pattern is no format */
    } else if (b.rate != pen->info.sample_rate) {
        nack(pen, f, RP_E_BAD_RATE);
    } else if (b.length > pen->buffer_bytes / 2u || b.length > RP_PLAYER_MAX_LENGTH) {
        nack(pen, f, RP_E_TOO_LARGE);
    } else if ((pen->staging = free_buffer(pen)) == NULL) {
        nack(pen, f, RP_E_TOO_LARGE); /* only if the buffers given to rp_pen_init are not distinct */
    } else {
        pen->upload = b;
        pen->received = 0;
        pen->crc = 0;
        pen->uploading = 1;
        ack(pen, f);
    }
}

static void handle_chunk(rp_pen *pen, const rp_frame *f) {
    uint32_t offset, i;
    const uint8_t *data;
    size_t n;
    if (rp_unpack_chunk(f->payload, f->length, &offset, &data, &n) != 0) {
        pen->uploading = 0; /* a chunk lost is an upload lost (docs/protocol.md) */
        nack(pen, f, RP_E_BAD_LENGTH);
    } else if (!pen->uploading) {
        nack(pen, f, RP_E_NO_UPLOAD);
    } else if (offset != pen->received) {
        pen->uploading = 0;
        nack(pen, f, RP_E_BAD_OFFSET);
    } else if (n > pen->upload.length * 2u - pen->received) {
        pen->uploading = 0; /* more bytes than BEGIN announced */
        nack(pen, f, RP_E_TOO_LARGE);
    } else {
        for (i = 0; i < n; i++) {
            store_byte(pen->staging, offset + i, data[i]);
        }
        pen->crc = rp_crc32(data, n, pen->crc);
        pen->received += (uint32_t)n;
    }
}

static void handle_commit(rp_pen *pen, const rp_frame *f) {
    uint16_t id;
    if (rp_unpack_commit(f->payload, f->length, &id) != 0) {
        pen->uploading = 0; /* a COMMIT ends the upload, even a malformed one */
        nack(pen, f, RP_E_BAD_LENGTH);
    } else if (!pen->uploading || id != pen->upload.id) {
        pen->uploading = 0; /* a COMMIT ends the upload, whatever its outcome */
        nack(pen, f, RP_E_NO_UPLOAD);
    } else {
        int loaded;
        pen->uploading = 0;
        if (pen->received != pen->upload.length * 2u) {
            nack(pen, f, RP_E_INCOMPLETE);
        } else if (pen->crc != pen->upload.crc32) {
            nack(pen, f, RP_E_CRC);
        } else {
            enter(pen);
            loaded = rp_player_load(pen->player, pen->staging, pen->upload.length,
                                    pen->upload.id);
            leave(pen);
            if (loaded != 0) {
                nack(pen, f, RP_E_TOO_LARGE);
            } else {
                ack(pen, f);
            }
        }
    }
}

void rp_pen_handle(rp_pen *pen, const rp_frame *f) {
    uint8_t p[RP_INFO_SIZE + RP_MAX_NAME];
    uint16_t version;
    uint32_t token;
    rp_state s;
    int set;
    switch (f->type) {
    case RP_HELLO:
        if (rp_unpack_hello(f->payload, f->length, &version) != 0) {
            nack(pen, f, RP_E_BAD_LENGTH);
        } else if (version != RP_PROTOCOL_VERSION) {
            /* INFO after the NACK: its first field tells the host which version to ask for. */
            nack(pen, f, RP_E_VERSION);
            send(pen, RP_INFO, f->seq, p, rp_pack_info(p, &pen->info));
        } else {
            send(pen, RP_INFO, f->seq, p, rp_pack_info(p, &pen->info));
        }
        break;
    case RP_PATTERN_BEGIN:
        handle_begin(pen, f);
        break;
    case RP_PATTERN_CHUNK:
        handle_chunk(pen, f);
        break;
    case RP_PATTERN_COMMIT:
        handle_commit(pen, f);
        break;
    case RP_SET_STATE:
        if (rp_unpack_state(f->payload, f->length, &s) != 0) {
            nack(pen, f, RP_E_BAD_LENGTH);
        } else {
            enter(pen);
            set = rp_player_set_state(pen->player, s.playing, s.gain, s.rate, s.fade_ms);
            leave(pen);
            if (set != 0) {
                nack(pen, f, RP_E_BAD_STATE);
            }
        }
        break;
    case RP_PING:
        if (rp_unpack_ping(f->payload, f->length, &token) != 0) {
            nack(pen, f, RP_E_BAD_LENGTH);
        } else {
            send(pen, RP_PONG, f->seq, p,
                 rp_pack_pong(p, token, pen->clock ? pen->clock(pen->ctx) : 0u));
        }
        break;
    case RP_CAPTURE_START:
        /* The Due has no accelerometer (no RP_FEATURE_ACCEL): whatever range and rate are
         * asked for, there is nothing to capture from. */
        nack(pen, f, f->length == RP_CAPTURE_START_SIZE ? RP_E_NO_SENSOR : RP_E_BAD_LENGTH);
        break;
    case RP_CAPTURE_STOP:
        /* Stop is idempotent, as on the Pico: with no capture under way there is nothing to
         * flush, so the ACK comes at once and says that no SAMPLES follow. */
        if (rp_unpack_capture_stop(f->payload, f->length) != 0) {
            nack(pen, f, RP_E_BAD_LENGTH);
        } else {
            ack(pen, f);
        }
        break;
    default:
        nack(pen, f, RP_E_UNKNOWN_TYPE);
        break;
    }
}

void rp_pen_feed(rp_pen *pen, const uint8_t *data, size_t n) {
    size_t i;
    rp_frame f;
    for (i = 0; i < n; i++) {
        if (rp_decoder_push(&pen->decoder, data[i], &f)) {
            rp_pen_handle(pen, &f);
        }
    }
}

void rp_pen_event(rp_pen *pen, uint8_t kind, uint32_t value) {
    uint8_t p[RP_EVENT_SIZE];
    send(pen, RP_EVENT, pen->event_seq++, p, rp_pack_event(p, kind, value));
}

void rp_pen_poll(rp_pen *pen, uint32_t underruns) {
    uint32_t swaps;
    uint16_t id;
    enter(pen);
    swaps = pen->player->swaps;
    id = pen->player->id;
    leave(pen);
    if (swaps != pen->reported_swaps) {
        pen->reported_swaps = swaps;
        rp_pen_event(pen, RP_EV_PATTERN, id);
    }
    if (pen->decoder.errors != pen->reported_errors) {
        pen->reported_errors = pen->decoder.errors;
        rp_pen_event(pen, RP_EV_DECODE_ERRORS, pen->decoder.errors);
    }
    if (underruns != pen->reported_underruns) {
        pen->reported_underruns = underruns;
        rp_pen_event(pen, RP_EV_UNDERRUN, underruns);
    }
}
