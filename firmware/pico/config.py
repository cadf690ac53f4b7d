"""The pen's settings: edit them for your build, then copy the folder to the Pico (README.md).

Pins are GPIO numbers of the Raspberry Pi Pico W / Pico 2 W. The wiring is in
docs/pen-hardware.md.
"""

NAME = "RealPen"  # BLE name and INFO name (UTF-8, at most 32 bytes; ≤ 8 keeps it in one advert)
MANUFACTURER = "RealPen"  # Device Information 0x2A29
MODEL = "RealPen Pico"  # Device Information 0x2A24

SAMPLE_RATE = 8000  # Hz; patterns are uploaded at this rate (INFO sample_rate)
MAX_PATTERN_BYTES = 32768  # the largest pattern (two buffers of it are allocated at boot)

# Q15 amplitude that full gain drives (0 … 32767). Lower it so that the amplifier at full gain
# cannot drive the actuator past its rated voltage: with the MAX98357A at its default 9 dB gain
# and a 5 V supply, full scale is several volts RMS, more than most LRAs are rated for.
GAIN_CAP = 32767

BLOCK_SAMPLES = 32  # samples rendered per audio interrupt: 4 ms at 8 kHz

# I2S to the MAX98357A (machine.I2S; on the rp2 port WS must be the pin after SCK).
I2S_ID = 0
I2S_SCK_PIN = 16  # MAX98357A BCLK
I2S_WS_PIN = 17  # MAX98357A LRC
I2S_SD_PIN = 18  # MAX98357A DIN
# machine.I2S ring buffer, bytes. The samples go out as 16-bit stereo (4 bytes a frame), and
# the rp2 driver moves 128-byte halves of its DMA buffer (4 ms at 8 kHz) out of this ring, so
# 128 is the least that works and keeps the queue short (README.md, "Audio buffering").
I2S_IBUF = 128
AMP_SD_PIN = None  # GPIO wired to the MAX98357A SD pin, driven high at boot; None if tied high

# BOOTSEL held during this long after a reset keeps the firmware from starting, so that the
# REPL (and mpremote) can reach the board: the firmware turns Ctrl-C off on the USB port.
STARTUP_WINDOW_MS = 1500

BLE = True  # advertise and serve the RealPen BLE service (needs a Pico W / Pico 2 W)

# Battery voltage, for EVENT battery and the BLE Battery service. On the Pico W and Pico 2 W the
# on-board VSYS divider (GPIO29) shares its pin with the radio's SPI clock, so reading it while
# BLE runs stops the radio; wire VSYS through your own divider to an ADC pin instead (e.g.
# 200 kΩ over 100 kΩ to GPIO28, as the Pico's own divider) and set the pin and ratio here.
BATTERY_ADC_PIN = None  # 26, 27 or 28; None: no battery reading (INFO says so)
BATTERY_DIVIDER = 3  # VSYS = ADC voltage × this
BATTERY_EMPTY_MV = 3300  # 0 % for the BLE battery level (a single LiPo cell, linear)
BATTERY_FULL_MV = 4200  # 100 %
