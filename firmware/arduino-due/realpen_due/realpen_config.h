/* What to change for your pen: the pattern it plays at boot, its drive limit, its name.
 *
 * The pattern is a C header exported by RealPen, e.g. for the bundled pencil at 8 kHz:
 *
 *     realpen export pencil --format c-header --rate 8000 \
 *         -o firmware/arduino-due/realpen_due/pattern.h
 *
 * Its identifiers are named after the pen (REALPEN_<NAME>_…, realpen_<name>_tactile); point
 * the three RP_DUE_TABLE* lines below at them. The table's rate becomes the pen's sample rate
 * (INFO sample_rate): the DAC timer runs at it, and uploads must be at it too.
 */
#ifndef REALPEN_CONFIG_H
#define REALPEN_CONFIG_H

#include "pattern.h"

#define RP_DUE_TABLE realpen_pencil_tactile
#define RP_DUE_TABLE_LENGTH REALPEN_PENCIL_LENGTH /* samples */
#define RP_DUE_RATE_HZ REALPEN_PENCIL_RATE_HZ     /* Hz */

/* The drive at full gain, Q15 (32767 = the DAC's full swing). Lower it until your amplifier at
 * its volume setting cannot drive the actuator past its rated voltage (see
 * docs/pen-hardware.md, "The gain cap"): SET_STATE gain 65535 then means this much and never
 * more. */
#define RP_DUE_GAIN_CAP 32767

/* Bytes of the largest pattern (INFO max_pattern_bytes). The sketch holds three buffers of
 * this size in RAM (playing, waiting for its wrap, being uploaded): 3 × 24 KiB of the Due's
 * 96 KiB. 24 KiB holds 1536 ms at 8 kHz. The boot pattern must fit too. */
#define RP_DUE_PATTERN_BYTES 24576u

/* The name INFO reports (UTF-8, at most 32 bytes). */
#define RP_DUE_NAME "RealPen Due"

/* 1: play the boot pattern at full gain from power-on, without a host (for checking the
 * wiring on the bench); 0: silent until a host sends SET_STATE. */
#define RP_DUE_PLAY_AT_BOOT 0

#define RP_DUE_FW_MAJOR 0
#define RP_DUE_FW_MINOR 1
#define RP_DUE_FW_PATCH 0

#endif /* REALPEN_CONFIG_H */
