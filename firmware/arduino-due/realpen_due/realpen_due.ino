/* RealPen on the Arduino Due (Atmel SAM3X8E): loops a tactile pattern through DAC0 and speaks
 * the RealPen pen protocol (docs/protocol.md) over the Due's native USB port (SerialUSB).
 *
 * At boot it plays nothing and holds the pattern of pattern.h (a `realpen export … --format
 * c-header` table, see realpen_config.h); a host uploads other patterns over USB and starts,
 * stops and scales the drive with SET_STATE. It has no accelerometer: INFO does not announce
 * FEATURE_ACCEL and CAPTURE_START is refused with E_NO_SENSOR (realpen_protocol.c). Build and
 * wiring: ../README.md.
 *
 * Timing: timer TC1 channel 0 (peripheral ID_TC3, interrupt TC3_IRQn) counts MCK/2 = 42 MHz
 * and interrupts at the pattern's rate. Each interrupt first writes the DAC code computed at
 * the previous one (so the DAC updates at a fixed point of the period, whatever the code below
 * costs) and then renders the next sample with the player. The player therefore runs in the
 * interrupt, one sample at a time: a SET_STATE takes effect one to two sample periods after
 * its frame is decoded (125-250 µs at 8 kHz), with no audio queue to drain and nothing that
 * can underrun. The protocol runs in loop(); the few instructions where it changes the
 * player's state are done with interrupts masked (guard() below).
 *
 * DAC: analogWrite(DAC0, …) once in setup() lets the Arduino core configure the DACC (its
 * peripheral clock, channel 0, free-running mode: ArduinoCore-sam cores/arduino/
 * wiring_analog.c, analogWrite); the interrupt then writes DACC_CDR directly, because
 * analogWrite itself busy-waits for the end of conversion. The DAC's output spans about 1/6 to
 * 5/6 of the 3.3 V reference, not 0 to 3.3 V: see ../README.md before wiring it.
 */
#include "realpen_config.h"
#include "realpen_player.h"
#include "realpen_protocol.h"

static_assert(RP_DUE_TABLE_LENGTH > 0, "pattern.h holds an empty table");
static_assert(RP_DUE_TABLE_LENGTH * 2u <= RP_DUE_PATTERN_BYTES,
              "the pattern of pattern.h is larger than RP_DUE_PATTERN_BYTES");
static_assert(RP_DUE_PATTERN_BYTES / 2u <= RP_PLAYER_MAX_LENGTH,
              "RP_DUE_PATTERN_BYTES is larger than the player can address");
static_assert(RP_DUE_RATE_HZ >= 1000u && RP_DUE_RATE_HZ <= 48000u,
              "the pattern's rate is outside 1-48 kHz");

static int16_t pattern_memory[RP_PEN_BUFFERS][RP_DUE_PATTERN_BYTES / 2u];
static rp_player player;
static rp_pen pen;
static volatile uint16_t next_code = 2048; /* mid-scale: the actuator at rest */
static bool host_seen = false;
static uint32_t last_poll_ms = 0;

void TC3_Handler(void) {
    int16_t sample;
    TC_GetStatus(TC1, 0); /* reading the status register acknowledges the RC compare */
    DACC->DACC_CDR = next_code;
    rp_player_render(&player, &sample, 1);
    next_code = rp_dac_code(sample);
}

static void guard(void *ctx, int enter) {
    (void)ctx;
    if (enter) {
        noInterrupts();
    } else {
        interrupts();
    }
}

static void write_usb(void *ctx, const uint8_t *data, size_t n) {
    (void)ctx;
    /* SerialUSB drops the bytes while no host holds the port open (DTR low), so a pen without
     * a host never blocks here. */
    SerialUSB.write(data, n);
}

static uint32_t clock_us(void *ctx) {
    (void)ctx;
    return micros();
}

static void start_dac_timer(uint32_t rate_hz) {
    pmc_set_writeprotect(false);
    pmc_enable_periph_clk(ID_TC3);
    TC_Configure(TC1, 0, TC_CMR_WAVE | TC_CMR_WAVSEL_UP_RC | TC_CMR_TCCLKS_TIMER_CLOCK1);
    /* 42 MHz / rate, rounded: exact for 8 kHz (5250); others are within 0.01 % of the rate. */
    TC_SetRC(TC1, 0, (VARIANT_MCK / 2u + rate_hz / 2u) / rate_hz);
    TC1->TC_CHANNEL[0].TC_IER = TC_IER_CPCS;
    TC1->TC_CHANNEL[0].TC_IDR = ~TC_IER_CPCS;
    NVIC_ClearPendingIRQ(TC3_IRQn);
    NVIC_SetPriority(TC3_IRQn, 0); /* the DAC's period comes first */
    NVIC_EnableIRQ(TC3_IRQn);
    TC_Start(TC1, 0);
}

void setup() {
    int16_t *buffers[RP_PEN_BUFFERS];
    rp_info info;
    uint32_t i;
    /* The header's 12-bit codes become the player's int16 samples once, here: 16·(code − 2048)
     * + 8, which the player turns back into the same code at full drive. */
    for (i = 0; i < RP_DUE_TABLE_LENGTH; i++) {
        pattern_memory[0][i] = rp_sample_of_code(RP_DUE_TABLE[i]);
    }
    for (i = 0; i < RP_PEN_BUFFERS; i++) {
        buffers[i] = pattern_memory[i];
    }
    rp_player_init(&player, RP_DUE_RATE_HZ, RP_DUE_GAIN_CAP);
    rp_player_load(&player, pattern_memory[0], RP_DUE_TABLE_LENGTH, 0);
    info.protocol = RP_PROTOCOL_VERSION;
    info.fw_major = RP_DUE_FW_MAJOR;
    info.fw_minor = RP_DUE_FW_MINOR;
    info.fw_patch = RP_DUE_FW_PATCH;
    info.sample_rate = RP_DUE_RATE_HZ;
    info.max_pattern_bytes = RP_DUE_PATTERN_BYTES;
    info.features = RP_FEATURE_USB | RP_FEATURE_RATE;
    info.name = RP_DUE_NAME;
    rp_pen_init(&pen, &player, buffers, RP_DUE_PATTERN_BYTES, &info, write_usb, clock_us, NULL);
    pen.guard = guard;
    if (RP_DUE_PLAY_AT_BOOT) {
        rp_player_set_state(&player, 1, RP_GAIN_ONE, RP_RATE_ONE, 5);
    }
    analogWriteResolution(12);
    analogWrite(DAC0, 2048);
    SerialUSB.begin(115200); /* USB CDC ignores the baud rate */
    start_dac_timer(RP_DUE_RATE_HZ);
}

void loop() {
    uint8_t in[64];
    size_t n = 0;
    uint32_t now;
    while (n < sizeof in && SerialUSB.available() > 0) {
        in[n++] = (uint8_t)SerialUSB.read();
    }
    if (n) {
        rp_pen_feed(&pen, in, n);
    }
    now = millis();
    if (now - last_poll_ms >= 100u) {
        last_poll_ms = now;
        if (SerialUSB.dtr()) {
            if (!host_seen) {
                /* EVENT boot once, to the first host that opens the port after power-on. */
                host_seen = true;
                rp_pen_event(&pen, RP_EV_BOOT, 0);
            }
            /* The player runs in the interrupt and never underruns. */
            rp_pen_poll(&pen, 0);
        }
    }
}
