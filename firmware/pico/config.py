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

# Pattern samples per block in the simulator (sim_main.py): 2 ms at 8 kHz, the blocks the Pico
# renders too (main.py derives its own from the I2S driver: one DMA half, 32 frames at twice
# SAMPLE_RATE, each pattern sample sent twice).
BLOCK_SAMPLES = 16

# I2S to the MAX98357A (machine.I2S; on the rp2 port WS must be the pin after SCK).
I2S_ID = 0
I2S_SCK_PIN = 16  # MAX98357A BCLK
I2S_WS_PIN = 17  # MAX98357A LRC
I2S_SD_PIN = 18  # MAX98357A DIN
# machine.I2S ring buffer, bytes. A block is written as 32 mono 16-bit samples (64 bytes); the
# driver copies a write into the ring only when all of it fits, and a ring of n bytes holds
# n - 1 (micropython extmod/machine_i2s.c:181-183, 326-328). 128 holds one block and never two:
# the least queue (README.md, "Audio buffering on the Pico"). Do not go below 65.
I2S_IBUF = 128
AMP_SD_PIN = None  # GPIO wired to the MAX98357A SD pin, driven high at boot; None if tied high

# BOOTSEL held during this long after a reset keeps the firmware from starting, so that the
# REPL (and mpremote) can reach the board: the firmware turns Ctrl-C off on the USB port.
STARTUP_WINDOW_MS = 1500

# While the pen is silent and no byte came, collect the garbage once this many bytes were
# allocated since the last collection (main.py), so that collections fall between strokes.
GC_IDLE_BYTES = 8192

# The LIS3DH accelerometer (docs/recording.md): I2C0 on GP4 (SDA) / GP5 (SCL) at 400 kHz, SDO to
# GND (address 0x18; 0x19 with SDO to 3V3), CS to 3V3 (I2C). Without one the pen still plays and
# INFO says it has no accelerometer; CAPTURE_START then gets NACK E_NO_SENSOR.
ACCEL = True
ACCEL_I2C_ID = 0
ACCEL_SDA_PIN = 4
ACCEL_SCL_PIN = 5
ACCEL_I2C_HZ = 400000
ACCEL_ADDRESS = 0x18
# Samples per I2C transfer: the I2S refill (a scheduled callback) cannot run inside a blocking
# transfer; 5 samples (33 bytes) take about 0.75 ms at 400 kHz, well within a 2 ms DMA half.
ACCEL_CHUNK_SAMPLES = 5

BLE = True  # advertise and serve the RealPen BLE service (needs a Pico W / Pico 2 W)

# Battery voltage, for EVENT battery and the BLE Battery service. On the Pico W and Pico 2 W the
# on-board VSYS divider (GPIO29) shares its pin with the radio's SPI clock, so reading it while
# BLE runs stops the radio; wire VSYS through your own divider to an ADC pin instead (e.g.
# 200 kΩ over 100 kΩ to GPIO28, as the Pico's own divider) and set the pin and ratio here.
BATTERY_ADC_PIN = None  # 26, 27 or 28; None: no battery reading (INFO says so)
BATTERY_DIVIDER = 3  # VSYS = ADC voltage × this
BATTERY_EMPTY_MV = 3300  # 0 % for the BLE battery level (a single LiPo cell, linear)
BATTERY_FULL_MV = 4200  # 100 %
