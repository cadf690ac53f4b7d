/* The RealPen pen protocol in plain C99 (docs/protocol.md): CRC-16/CCITT-FALSE, COBS, a
 * streaming frame decoder with a fixed buffer, the message structs, and the pen's side of the
 * conversation (HELLO, pattern upload, SET_STATE, PING, and capture, which the Due refuses: it
 * has no accelerometer).
 *
 * It mirrors src/realpen/device/protocol.py byte for byte and passes the same test vectors
 * (tests/data/protocol_vectors.json, checked by tests/test_due.py). No malloc, no globals:
 * every state lives in a struct the caller owns, so the sketch can put it in static memory and
 * the host tests can make as many as they like.
 *
 * A frame on the wire is COBS([type u8][seq u8][payload][crc16 u16 LE]) followed by 0x00.
 */
#ifndef REALPEN_PROTOCOL_H
#define REALPEN_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>

#include "realpen_player.h"

#ifdef __cplusplus
extern "C" {
#endif

#define RP_PROTOCOL_VERSION 1u
#define RP_MAX_FRAME 256u  /* bytes of the largest decoded frame: type + seq + payload + CRC */
#define RP_MAX_CHUNK 180u  /* pattern bytes per PATTERN_CHUNK */
#define RP_MAX_NAME 32u    /* bytes of the pen's UTF-8 name in INFO */
/* Longest COBS encoding the decoder keeps, as protocol.py's FrameDecoder.max_encoded. */
#define RP_MAX_ENCODED (RP_MAX_FRAME + RP_MAX_FRAME / 254u + 2u)
/* Longest frame on the wire: COBS of RP_MAX_FRAME bytes plus the 0x00 delimiter. */
#define RP_MAX_WIRE (RP_MAX_FRAME + RP_MAX_FRAME / 254u + 2u)

/* Frame types. */
#define RP_HELLO 0x01u
#define RP_INFO 0x02u
#define RP_PATTERN_BEGIN 0x10u
#define RP_PATTERN_CHUNK 0x11u
#define RP_PATTERN_COMMIT 0x12u
#define RP_SET_STATE 0x20u
#define RP_PING 0x30u
#define RP_PONG 0x31u
#define RP_ACK 0x40u
#define RP_NACK 0x41u
#define RP_EVENT 0x50u
#define RP_CAPTURE_START 0x60u
#define RP_CAPTURE_STOP 0x61u
#define RP_SAMPLES 0x62u

/* NACK codes. */
#define RP_E_UNKNOWN_TYPE 1u
#define RP_E_BAD_LENGTH 2u
#define RP_E_VERSION 3u
#define RP_E_TOO_LARGE 4u
#define RP_E_BAD_FORMAT 5u
#define RP_E_BAD_OFFSET 6u
#define RP_E_CRC 7u
#define RP_E_INCOMPLETE 8u
#define RP_E_NO_UPLOAD 9u
#define RP_E_BAD_RATE 10u
#define RP_E_BAD_STATE 11u
#define RP_E_NO_SENSOR 12u
#define RP_E_BAD_CAPTURE 13u

/* EVENT kinds. */
#define RP_EV_BOOT 1u
#define RP_EV_UNDERRUN 2u
#define RP_EV_BATTERY 3u
#define RP_EV_PATTERN 4u
#define RP_EV_DECODE_ERRORS 5u
#define RP_EV_OVERRUN 6u          /* sensor FIFO overruns in this capture so far */
#define RP_EV_CAPTURE_DROPPED 7u  /* SAMPLES blocks of this capture the pen could not send */

#define RP_FORMAT_S16LE 1u

#define RP_FEATURE_USB 1u
#define RP_FEATURE_BLE 2u
#define RP_FEATURE_BATTERY 4u
#define RP_FEATURE_RATE 8u
#define RP_FEATURE_ACCEL 16u /* an accelerometer to capture from; the Due has none */

/* Capture (SAMPLES blocks): at most a LIS3DH FIFO's worth of x, y, z int16 LE samples. */
#define RP_MAX_BLOCK_SAMPLES 32u
#define RP_SAMPLE_BYTES 6u
#define RP_SAMPLES_OVERRUN 1u /* SAMPLES flags bit: the sensor's FIFO overran before the block */

/* Payload sizes of the fixed structs (little-endian, packed). */
#define RP_HELLO_SIZE 2u
#define RP_INFO_SIZE 17u /* plus the name, 0 … RP_MAX_NAME bytes */
#define RP_BEGIN_SIZE 15u
#define RP_CHUNK_HEAD 4u /* plus 1 … RP_MAX_CHUNK bytes */
#define RP_COMMIT_SIZE 2u
#define RP_STATE_SIZE 7u
#define RP_PING_SIZE 4u
#define RP_PONG_SIZE 8u
#define RP_ACK_SIZE 1u
#define RP_NACK_SIZE 2u
#define RP_EVENT_SIZE 5u
#define RP_CAPTURE_START_SIZE 3u
#define RP_SAMPLES_HEAD 10u /* plus 1 … RP_MAX_BLOCK_SAMPLES samples of RP_SAMPLE_BYTES */

/* --- checksums ------------------------------------------------------------------------- */

/* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR) of n bytes,
 * continuing from crc (start with 0xFFFF). "123456789" gives 0x29B1. */
uint16_t rp_crc16(const uint8_t *data, size_t n, uint16_t crc);

/* CRC-32 as zlib.crc32 / binascii.crc32 (IEEE 802.3, reflected, init and final XOR
 * 0xFFFFFFFF), continuing from crc (start with 0). "123456789" gives 0xCBF43926. */
uint32_t rp_crc32(const uint8_t *data, size_t n, uint32_t crc);

/* --- COBS (Cheshire & Baker 1999) ------------------------------------------------------ */

/* Encodes n bytes into out (capacity cap); returns the encoded length (always ≥ 1), or 0
 * when it does not fit. At most n + n/254 + 1 bytes. No delimiter is appended. */
size_t rp_cobs_encode(const uint8_t *in, size_t n, uint8_t *out, size_t cap);

/* Decodes n COBS bytes (no delimiter) into out (capacity cap). Returns 0 and sets *out_n,
 * -1 if malformed (a zero byte inside, a block running past the end), -2 if it does not fit. */
int rp_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_n);

/* --- frames ---------------------------------------------------------------------------- */

/* One frame for the wire: COBS(type, seq, payload, CRC-16 LE) + 0x00 into out (capacity cap,
 * RP_MAX_WIRE always suffices). Returns its length, or 0 if the frame would be larger than
 * RP_MAX_FRAME or does not fit out. */
size_t rp_encode_frame(uint8_t type, uint8_t seq, const uint8_t *payload, size_t n,
                       uint8_t *out, size_t cap);

typedef struct {
    uint8_t type;
    uint8_t seq;
    const uint8_t *payload; /* points into the decoder; valid until its next push */
    size_t length;          /* payload bytes */
} rp_frame;

/* Frames out of a byte stream split anywhere. Like protocol.py's FrameDecoder: a frame whose
 * COBS, CRC or length is wrong is dropped and counted in errors; decoding resumes after the
 * next 0x00; empty frames (0x00 0x00) are ignored; nothing grows past the fixed buffers. */
typedef struct {
    uint8_t encoded[RP_MAX_ENCODED];
    uint8_t body[RP_MAX_ENCODED]; /* a COBS block of RP_MAX_ENCODED bytes decodes shorter */
    size_t length;
    uint8_t overflow;
    uint32_t errors; /* frames dropped so far */
} rp_decoder;

void rp_decoder_init(rp_decoder *d);

/* Feeds one byte; returns 1 and fills *frame when it completes a good frame, else 0. */
int rp_decoder_push(rp_decoder *d, uint8_t byte, rp_frame *frame);

/* --- message structs ------------------------------------------------------------------- */
/* Each pack writes the payload into out (large enough: the RP_*_SIZE above) and returns its
 * length; each unpack returns 0, or -1 when the payload has the wrong length. */

typedef struct {
    uint16_t protocol;
    uint8_t fw_major, fw_minor, fw_patch;
    uint32_t sample_rate;       /* Hz */
    uint32_t max_pattern_bytes; /* bytes */
    uint32_t features;          /* RP_FEATURE_* bits */
    const char *name;           /* UTF-8, at most RP_MAX_NAME bytes are sent */
} rp_info;

typedef struct {
    uint16_t id;
    uint32_t length; /* samples */
    uint32_t rate;   /* Hz */
    uint8_t format;  /* RP_FORMAT_* */
    uint32_t crc32;  /* of the sample bytes, zlib's CRC-32 */
} rp_begin;

typedef struct {
    uint8_t playing;  /* 0 or 1 */
    uint16_t gain;    /* 0 … RP_GAIN_ONE */
    uint16_t rate;    /* Q12 playback-rate factor */
    uint16_t fade_ms; /* ramp time, ms */
} rp_state;

size_t rp_pack_hello(uint8_t *out, uint16_t version);
int rp_unpack_hello(const uint8_t *p, size_t n, uint16_t *version);
size_t rp_pack_info(uint8_t *out, const rp_info *info);
/* name_out receives the name's bytes (not NUL-terminated, *name_n of them). */
int rp_unpack_info(const uint8_t *p, size_t n, rp_info *info, const uint8_t **name_out,
                   size_t *name_n);
size_t rp_pack_begin(uint8_t *out, const rp_begin *b);
int rp_unpack_begin(const uint8_t *p, size_t n, rp_begin *b);
size_t rp_pack_chunk(uint8_t *out, uint32_t offset, const uint8_t *data, size_t n);
int rp_unpack_chunk(const uint8_t *p, size_t n, uint32_t *offset, const uint8_t **data,
                    size_t *data_n);
size_t rp_pack_commit(uint8_t *out, uint16_t id);
int rp_unpack_commit(const uint8_t *p, size_t n, uint16_t *id);
size_t rp_pack_state(uint8_t *out, const rp_state *s);
int rp_unpack_state(const uint8_t *p, size_t n, rp_state *s);
size_t rp_pack_ping(uint8_t *out, uint32_t token);
int rp_unpack_ping(const uint8_t *p, size_t n, uint32_t *token);
size_t rp_pack_pong(uint8_t *out, uint32_t token, uint32_t device_us);
int rp_unpack_pong(const uint8_t *p, size_t n, uint32_t *token, uint32_t *device_us);
size_t rp_pack_ack(uint8_t *out, uint8_t type);
int rp_unpack_ack(const uint8_t *p, size_t n, uint8_t *type);
size_t rp_pack_nack(uint8_t *out, uint8_t type, uint8_t code);
int rp_unpack_nack(const uint8_t *p, size_t n, uint8_t *type, uint8_t *code);
size_t rp_pack_event(uint8_t *out, uint8_t kind, uint32_t value);
int rp_unpack_event(const uint8_t *p, size_t n, uint8_t *kind, uint32_t *value);
/* CAPTURE_START: range in g, output rate in Hz. CAPTURE_STOP has no payload: its unpack only
 * checks that. SAMPLES: first sample's index, the pen's µs clock, range in g, flags, then
 * 1 … RP_MAX_BLOCK_SAMPLES samples (data, n bytes; pack returns 0 for a count out of range). */
size_t rp_pack_capture_start(uint8_t *out, uint8_t range_g, uint16_t rate_hz);
int rp_unpack_capture_start(const uint8_t *p, size_t n, uint8_t *range_g, uint16_t *rate_hz);
int rp_unpack_capture_stop(const uint8_t *p, size_t n);
typedef struct {
    uint32_t first; /* index of the block's first sample since CAPTURE_START */
    uint32_t t_us;  /* the pen's clock when the sensor's FIFO level was read, µs */
    uint8_t range_g;
    uint8_t flags;  /* RP_SAMPLES_OVERRUN */
} rp_samples;
size_t rp_pack_samples(uint8_t *out, const rp_samples *s, const uint8_t *data, size_t n);
int rp_unpack_samples(const uint8_t *p, size_t n, rp_samples *s, const uint8_t **data,
                      size_t *data_n);

/* --- the pen --------------------------------------------------------------------------- */

#define RP_PEN_BUFFERS 3 /* playing, waiting for its wrap, being uploaded */

/* Writes n bytes (whole frames) to the link; the sketch sends them over SerialUSB. */
typedef void (*rp_write_fn)(void *ctx, const uint8_t *data, size_t n);
/* The pen's clock in µs (wraps at 2**32), for PONG. */
typedef uint32_t (*rp_clock_fn)(void *ctx);
/* Called with 1 before the pen touches the player and with 0 after, when the player runs in
 * an interrupt (the Due's DAC timer): the sketch masks interrupts for those few instructions. */
typedef void (*rp_guard_fn)(void *ctx, int enter);

/* The pen's side of the protocol: decodes the link's bytes, answers, uploads patterns into
 * whichever of its three buffers the player is not using, and drives the player. */
typedef struct {
    rp_decoder decoder;
    rp_player *player;
    int16_t *buffers[RP_PEN_BUFFERS];
    uint32_t buffer_bytes; /* each buffer's size = INFO max_pattern_bytes */
    rp_info info;
    rp_write_fn write;
    rp_clock_fn clock;
    rp_guard_fn guard; /* NULL after rp_pen_init; set it when the player runs in an interrupt */
    void *ctx;
    /* upload in progress */
    uint8_t uploading;
    int16_t *staging;
    rp_begin upload;
    uint32_t received; /* bytes */
    uint32_t crc;      /* running CRC-32 of the bytes received */
    /* events */
    uint8_t event_seq;
    uint32_t reported_swaps;
    uint32_t reported_errors;
    uint32_t reported_underruns;
} rp_pen;

/* buffers: RP_PEN_BUFFERS distinct arrays of buffer_bytes bytes each (even); info->
 * max_pattern_bytes is set to buffer_bytes. write must not be NULL; clock may be NULL (0). */
void rp_pen_init(rp_pen *pen, rp_player *player, int16_t *const buffers[RP_PEN_BUFFERS],
                 uint32_t buffer_bytes, const rp_info *info, rp_write_fn write,
                 rp_clock_fn clock, void *ctx);

/* Feeds bytes from the link; complete frames are handled (and answered) at once. */
void rp_pen_feed(rp_pen *pen, const uint8_t *data, size_t n);

/* Handles one decoded frame (rp_pen_feed calls it). */
void rp_pen_handle(rp_pen *pen, const rp_frame *frame);

/* Sends an EVENT with the pen's own counter as seq. */
void rp_pen_event(rp_pen *pen, uint8_t kind, uint32_t value);

/* Sends the events due: EV_PATTERN when the player swapped patterns, EV_DECODE_ERRORS and
 * EV_UNDERRUN (underruns: the sketch's count) when their counts grew since the last report.
 * Call it from the main loop, e.g. every 100 ms, which also bounds the events' rate. */
void rp_pen_poll(rp_pen *pen, uint32_t underruns);

#ifdef __cplusplus
}
#endif

#endif /* REALPEN_PROTOCOL_H */
