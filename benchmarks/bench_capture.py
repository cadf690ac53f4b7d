"""The accelerometer capture's timing budget on the pen, from the simulator's virtual clock.

Runs ``firmware/pico/sim_timing.py`` under the MicroPython Unix port: the firmware's own LIS3DH
driver and capture against the register-level LIS3DH model on a simulated I2C bus that charges
every transfer its bits, beside the I2S refills the Pico's audio asks for every 2 ms (the
firmware's player renders each of them with ``--play``). Prints, per configuration: simulated
time, samples taken and read, blocks, the bus time per burst (mean and longest), the longest
single transfer (the longest an I2S refill waits), the bus's busy share, late refills
(underruns), FIFO overruns and the samples lost (the model's count and the pen's estimate).

Configurations: the firmware's (400 kHz, 5 samples a transfer, watermark 16); one transfer per
burst (32 samples: refills wait 4.3 ms, more than a 2 ms DMA half); a 100 kHz bus; and a drain
held back to every 40 ms (the FIFO overruns).

Usage: python benchmarks/bench_capture.py [--minutes 10] [--play]
"""

from __future__ import annotations

import argparse
import json
import subprocess
from pathlib import Path

from realpen.device.sim import find_micropython

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware" / "pico"

CONFIGURATIONS = {
    "firmware (400 kHz, 5 a transfer, watermark 16)": {},
    "one transfer a burst (chunk 32)": {"chunk": 32},
    "100 kHz bus": {"bus_hz": 100000},
    "drain every 40 ms": {"look_every_us": 40000},
}


def run(minutes: float, play: bool, options: dict) -> dict:
    words = [f"minutes={minutes}", f"play={int(play)}"]
    words += [f"{key}={value}" for key, value in options.items()]
    result = subprocess.run([find_micropython(), "sim_timing.py", *words], cwd=FIRMWARE,
                            capture_output=True, text=True, check=True)
    return json.loads(result.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="simulated minutes each")
    parser.add_argument("--play", action="store_true",
                        help="render the pattern with the firmware's player at every refill")
    args = parser.parse_args()
    for name, options in CONFIGURATIONS.items():
        r = run(args.minutes, args.play, options)
        print(f"{name}:")
        print(f"  {r['simulated_s']:.0f} s simulated at {r['true_rate_hz']:.1f} Hz: "
              f"{r['samples']} samples taken, {r['read']} read, {r['blocks']} blocks "
              f"(largest {r['largest_block']})")
        print(f"  bus per burst {r['mean_burst_us'] / 1000:.2f} ms mean, "
              f"{r['longest_burst_us'] / 1000:.2f} ms longest; longest transfer "
              f"{r['longest_transfer_us'] / 1000:.2f} ms; bus busy {r['bus_busy_percent']:.1f} %")
        print(f"  I2S refills {r['refills']}, late {r['late_refills']} (longest wait "
              f"{r['longest_refill_wait_us'] / 1000:.2f} ms); overruns {r['overruns']}, "
              f"samples lost {r['lost']} (pen's estimate {r['lost_estimated']})")


if __name__ == "__main__":
    main()
