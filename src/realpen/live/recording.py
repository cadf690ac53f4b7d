"""The live app's "Record a pen" session: takes, their files, and the build of a profile.

A take is what one press of Record gives: the pen's accelerometer, captured through the
server's pen bridge (:meth:`realpen.device.bridge.PenBridge.capture`) while the take runs, and
the friction sound that the page recorded from its microphone and uploads afterwards as a WAV,
in chunks (each within the server's request-body limit). Either part alone makes a take. The
takes' files live in a temporary folder of the server for as long as the server runs; a take
dropped is deleted at once.

:meth:`Recorder.build` makes a profile from the kept takes on a thread of its own and installs
it in the user's profiles folder, where the live app's catalog offers it at once
(:meth:`realpen.live.catalog.Catalog.add`). The profile's tactile pattern is built from the
longest kept take with an accelerometer part and its sound from the longest kept take with a
sound part: the method analyses one continuous recording, and joining takes would put their
seams into the analysis.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import shutil
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from realpen.errors import ParameterError, RealPenError, fail

__all__ = ["Recorder", "Take", "RecorderBusy", "BuildJob", "MAX_TAKES", "MAX_TAKE_S",
           "MAX_SOUND_BYTES", "MAX_SESSION_BYTES", "SOUND_RATES", "DEFAULT_ACTUATOR",
           "MIC_CLIP", "accelerometer_available"]

MAX_TAKES = 24  # takes a session holds at once (drop some to record more)
MAX_TAKE_S = 300.0  # the longest take, seconds (the method needs a few seconds of writing)
SOUND_RATES = (44100, 48000)  # what a browser's microphone gives at the page's request, Hz
MAX_SOUND_BYTES = int(max(SOUND_RATES) * 4 * MAX_TAKE_S) + 4096  # float32 mono + headers
MAX_SESSION_BYTES = 512 * 1024 * 1024  # the takes' sound files together, in the temporary folder
DEFAULT_ACTUATOR = "lra:f0=175,q=8"  # as `realpen profile build`
ACTUATOR_MODELS = ("lra", "piezo", "flat")  # the page may name a model, never a server file
MIC_CLIP = 0.999  # a microphone sample at or above this (of full scale) counts as clipped
STOP_WAIT_S = 5.0  # how long stopping a take waits for the pen's last samples, seconds
G = 9.80665  # m/s² per g


class RecorderBusy(RealPenError):
    """The session is doing something that must end first (a take runs, a build runs)."""


def accelerometer_available(device) -> bool | None:
    """Whether the server's pen device can capture its accelerometer now: True (a connected
    pen that says it has one), False (no pen, or one without), None (connected, but it did
    not say)."""
    if getattr(device, "capture", None) is None:
        return False
    status = device.status() if hasattr(device, "status") else {}
    if not status.get("connected"):
        return False
    info = status.get("info") or {}
    features = info.get("features")
    if features is None:
        return None
    from realpen.device.protocol import FEATURE_ACCEL

    return bool(int(features) & FEATURE_ACCEL)


def _db(value: float) -> float | None:
    """``value`` (of full scale) in dB, None for silence (JSON has no -inf)."""
    return round(20 * math.log10(value), 2) if value > 0 else None


@dataclasses.dataclass
class AccelPart:
    """A take's accelerometer part once stopped (levels in m/s² and in g)."""

    path: Path
    seconds: float
    rate_hz: float
    samples: int
    rms_ms2: list[float]
    peak_g: float
    clipped: int
    gaps: int
    overruns: int
    dropped: int

    def to_json(self) -> dict:
        """The part as the page shows it (no path)."""
        return {key: value for key, value in dataclasses.asdict(self).items() if key != "path"}


@dataclasses.dataclass
class SoundPart:
    """A take's microphone part once uploaded: rate in Hz, levels in dB of full scale."""

    path: Path
    seconds: float
    rate: int
    rms_dbfs: float | None
    peak_dbfs: float | None
    clipped: int

    def to_json(self) -> dict:
        """The part as the page shows it (no path)."""
        return {key: value for key, value in dataclasses.asdict(self).items() if key != "path"}


class _AccelLive:
    """The accelerometer's blocks and events as they arrive, assembled
    (:class:`realpen.device.capture.CaptureAssembler`): fed on the bridge's thread, read on
    the routes'."""

    def __init__(self, assembler):
        self.assembler = assembler
        self.lock = threading.Lock()
        self.limit = int(MAX_TAKE_S * assembler.nominal_rate_hz)  # samples a take may hold
        self.full = False

    def __call__(self, item) -> None:
        with self.lock:
            if self.assembler.received >= self.limit:
                self.full = True  # memory stays bounded: a take that runs on keeps its limit
                return
            self.assembler.feed(item)

    @property
    def samples(self) -> int:
        """Samples received so far."""
        with self.lock:
            return self.assembler.received

    def level(self) -> dict:
        """The live level: RMS per axis of the vibration (about the mean, so without gravity)
        over the newest samples in m/s², the peak in g, the range, samples and clipped ones."""
        with self.lock:
            level, samples = self.assembler.level(), self.assembler.received
            range_g, overruns = self.assembler.range_g, self.assembler.overruns
        return {"samples": samples, "rms_ms2": [round(v * G, 4) for v in level.rms_g],
                "peak_g": round(max(level.peak_g), 4), "range_g": range_g,
                "clipped": int(sum(level.clipped)), "overruns": overruns}


@dataclasses.dataclass
class Take:
    """One take: its folder, when it started, its parts, and whether Build uses it."""

    id: int
    folder: Path
    started_at: str
    keep: bool = True
    running: bool = False
    stopping: bool = False
    accel: AccelPart | None = None
    sound: SoundPart | None = None
    accel_problem: str | None = None
    sound_bytes: int = 0  # bytes of the sound WAV received so far
    live: _AccelLive | None = dataclasses.field(default=None, repr=False)
    run: object | None = dataclasses.field(default=None, repr=False)
    started: float = 0.0  # time.monotonic() at the start

    @property
    def seconds(self) -> float:
        """The take's length: its longer part, or the time since it started while it runs."""
        if self.running:
            return time.monotonic() - self.started
        return max(self.accel.seconds if self.accel else 0.0,
                   self.sound.seconds if self.sound else 0.0)

    def to_json(self) -> dict:
        """The take as the page lists it."""
        return {"id": self.id, "started_at": self.started_at, "keep": self.keep,
                "running": self.running, "seconds": round(self.seconds, 3),
                "accel": self.accel.to_json() if self.accel else None,
                "accel_problem": self.accel_problem,
                "sound": self.sound.to_json() if self.sound else None,
                "sound_bytes": self.sound_bytes}


@dataclasses.dataclass
class BuildJob:
    """A profile build under way or finished: ``state`` is ``running``, ``done`` or
    ``failed``; ``fraction`` 0 … 1 of the work; ``stage`` what it does; ``profile`` the
    installed pen's name when done; ``detail`` the one-line reason when failed."""

    id: int
    name: str
    state: str = "running"
    stage: str = "starting"
    fraction: float = 0.0
    profile: str | None = None
    detail: str | None = None
    summary: str | None = None
    notes: list[str] = dataclasses.field(default_factory=list)

    def to_json(self) -> dict:
        """The job as the page polls it."""
        return dataclasses.asdict(self)


class Recorder:
    """A server's recording session (see the module doc). Thread-safe: routes run on worker
    threads, the accelerometer's samples arrive on the pen bridge's thread.

    Args:
        device: the server's pen device (a :class:`~realpen.device.bridge.PenBridge` can
            capture; anything without ``capture`` records the microphone only).
        catalog: the live app's :class:`~realpen.live.catalog.Catalog`, where a built pen is
            offered at once.
        folder: where the takes' files go (default: a new temporary folder, removed when the
            recorder is closed or the server exits).
        profiles_dir: where a built pen is installed (default:
            :func:`realpen.io.paths.user_profiles_dir`).
    """

    def __init__(self, device, catalog, folder: Path | None = None,
                 profiles_dir: Path | None = None):
        self.device, self.catalog = device, catalog
        self._tmp = None if folder is not None else tempfile.TemporaryDirectory(
            prefix="realpen-takes-")
        self.folder = Path(folder if folder is not None else self._tmp.name)
        self.profiles_dir = profiles_dir
        self._lock = threading.Lock()
        self._takes: dict[int, Take] = {}
        self._next_take = 1
        self._job: BuildJob | None = None
        self._next_job = 1

    # ---- status --------------------------------------------------------------------------

    def status(self) -> dict:
        """What the page needs: the pen (connected, accelerometer), the takes, the current
        take's id, the last build and the limits."""
        device = self.device
        status = device.status() if hasattr(device, "status") else {}
        with self._lock:
            takes = [take.to_json() for take in self._takes.values()]
            running = next((t.id for t in self._takes.values() if t.running), None)
            job = self._job.to_json() if self._job else None
        return {"pen": {"name": getattr(device, "name", "none"),
                        "connected": bool(status.get("connected")),
                        "message": status.get("message"),
                        "accelerometer": accelerometer_available(device)},
                "takes": takes, "running": running, "build": job,
                "limits": {"max_takes": MAX_TAKES, "max_take_s": MAX_TAKE_S,
                           "max_sound_bytes": MAX_SOUND_BYTES, "sound_rates": list(SOUND_RATES)},
                "default_actuator": DEFAULT_ACTUATOR}

    def take(self, take_id: int) -> Take:
        """The take ``take_id``.

        Raises:
            RealPenError: no such take (dropped, or never made).
        """
        with self._lock:
            found = self._takes.get(take_id)
        if found is None:
            raise RealPenError(f"take {take_id}: no such take (dropped?)")
        return found

    def live(self) -> dict:
        """The running take's live accelerometer level (``accel`` None without one)."""
        with self._lock:
            take = next((t for t in self._takes.values() if t.running), None)
        if take is None:
            return {"take": None, "seconds": 0.0, "accel": None, "accel_problem": None}
        problem = take.accel_problem or (getattr(take.run, "error", None) if take.run else None)
        if problem is None and take.live is not None and take.live.full:
            problem = f"the take reached {MAX_TAKE_S:g} s, the longest kept; stop it"
        return {"take": take.id, "seconds": round(take.seconds, 3),
                "accel": take.live.level() if take.live else None, "accel_problem": problem}

    # ---- takes ---------------------------------------------------------------------------

    def start_take(self, *, accelerometer: bool = True, range_g: int = 2) -> Take:
        """Start a take: capture the pen's accelerometer when asked and the pen can.

        Args:
            accelerometer: capture the pen's accelerometer (if the server drives a pen).
            range_g: the accelerometer's full-scale range in g (2, 4, 8 or 16).

        Raises:
            RecorderBusy: a take or a build runs, or the session holds :data:`MAX_TAKES`.
            ParameterError: (``range_g``) not a range the sensor has.
        """
        from realpen.device.protocol import CAPTURE_RANGES, CAPTURE_RATE

        if range_g not in CAPTURE_RANGES:
            raise ParameterError("range_g", f"must be one of {', '.join(map(str, CAPTURE_RANGES))}"
                                            f" g, got {range_g}")
        with self._lock:
            if any(t.running for t in self._takes.values()):
                raise RecorderBusy("a take is already running; stop it first")
            if self._job is not None and self._job.state == "running":
                raise RecorderBusy("a profile is being built; record when it is done")
            if len(self._takes) >= MAX_TAKES:
                raise RecorderBusy(f"the session holds {MAX_TAKES} takes, the most it keeps; "
                                   f"drop some first")
            take_id, self._next_take = self._next_take, self._next_take + 1
            folder = self.folder / f"take-{take_id}"
            folder.mkdir(parents=True)
            take = Take(take_id, folder, datetime.datetime.now(datetime.UTC).isoformat(
                timespec="seconds"), running=True, started=time.monotonic())
            self._takes[take_id] = take
        if accelerometer:
            capture = getattr(self.device, "capture", None)
            if capture is None or not self.device.status().get("connected"):
                take.accel_problem = "no pen connected on the server's side"
            else:
                from realpen.device.capture import CaptureAssembler

                take.live = _AccelLive(CaptureAssembler(range_g, CAPTURE_RATE))
                take.run = capture(take.live, range_g=range_g, rate_hz=CAPTURE_RATE)
        return take

    def stop_take(self, take_id: int) -> Take:
        """Stop the take: its capture ends and is written (NPZ, m/s², the pen's timestamps'
        rate). A take with no accelerometer samples keeps only its reason.

        Raises:
            RealPenError: no such take.
        """
        take = self.take(take_id)
        with self._lock:
            if not take.running or take.stopping:  # a second Stop (a double click) waits not
                return take
            take.stopping = True
        run, live = take.run, take.live
        if run is not None:
            error = run.stop(STOP_WAIT_S)
            if live is not None and live.samples:
                try:
                    take.accel = self._write_accel(take, live, run)
                except RealPenError as problem:
                    take.accel_problem = str(problem)
            if error and take.accel is None:
                take.accel_problem = error
            elif error:
                take.accel_problem = f"the capture ended early: {error}"
            elif take.accel is None:
                take.accel_problem = "the pen sent no samples"
        with self._lock:
            take.running = take.stopping = False
        return take

    def _write_accel(self, take: Take, live: _AccelLive, run) -> AccelPart:
        from realpen.device.capture import write_capture

        with live.lock:
            info = getattr(run, "info", None)
            if hasattr(info, "firmware_version"):  # a PenInfo: the pen, for the provenance
                live.assembler.info = info
            live.assembler.port = getattr(self.device, "name", None)
            capture = live.assembler.result(host_dropped=getattr(run, "host_dropped", 0))
        path = write_capture(capture, take.folder / "accel.npz")
        samples = np.nan_to_num(capture.samples, nan=0.0)
        rms = np.sqrt(np.mean((samples - samples.mean(axis=0)) ** 2, axis=0))
        peak_g = float(np.max(np.abs(samples))) / G if len(samples) else 0.0
        return AccelPart(path, round(capture.duration_s, 3), round(float(capture.rate_hz), 3),
                         capture.frames, [round(float(v), 4) for v in rms], round(peak_g, 4),
                         int(sum(capture.clipped)), len(capture.gaps),
                         int(capture.provenance.get("overruns", 0)),
                         int(capture.provenance.get("blocks_dropped_by_pen", 0))
                         + int(capture.provenance.get("blocks_dropped_by_host", 0)))

    def add_sound(self, take_id: int, offset: int, data: bytes) -> Take:
        """Append a chunk of the take's microphone WAV, at byte ``offset`` (chunks in order).

        Raises:
            RealPenError: no such take, a take still running or whose sound is complete, a
                chunk out of order, or more than :data:`MAX_SOUND_BYTES` in all.
        """
        take = self.take(take_id)
        with self._lock:
            if take.running:
                raise RecorderBusy(f"take {take_id}: stop it before uploading its sound")
            if take.sound is not None:
                raise fail(f"take {take_id}", "its sound is already complete")
            if offset != take.sound_bytes:
                raise fail(f"take {take_id}", f"sound chunk at byte {offset:,}, expected "
                                              f"{take.sound_bytes:,} (chunks in order)")
            if offset + len(data) > MAX_SOUND_BYTES:
                raise fail(f"take {take_id}", f"the sound would be over {MAX_SOUND_BYTES:,} "
                                              f"bytes ({MAX_TAKE_S:g} s at 48 kHz, float)")
            held = sum(t.sound_bytes for t in self._takes.values())
            if held + len(data) > MAX_SESSION_BYTES:
                raise RecorderBusy(f"the takes' sounds would be over {MAX_SESSION_BYTES:,} bytes "
                                   f"in all; drop some takes first")
            with open(take.folder / "sound.part", "ab") as handle:
                handle.write(data)
            take.sound_bytes += len(data)
        return take

    def end_sound(self, take_id: int) -> Take:
        """The take's WAV is complete: check it (mono, 44.1 or 48 kHz, 16-bit or float, at
        most :data:`MAX_TAKE_S`) and measure it. A bad one is deleted.

        Raises:
            RealPenError: no such take, nothing uploaded, or not such a WAV (one line).
        """
        take = self.take(take_id)
        with self._lock:
            if take.sound is not None:
                return take
            part = take.folder / "sound.part"
            if not take.sound_bytes or not part.exists():
                raise fail(f"take {take_id}", "no sound uploaded")
            try:
                take.sound = _check_sound(part, take.folder / "sound.wav", f"take {take_id} sound")
            finally:
                part.unlink(missing_ok=True)
                if take.sound is None:
                    take.sound_bytes = 0
        return take

    def set_keep(self, take_id: int, keep: bool) -> Take:
        """Keep the take for Build, or leave it out (it stays listed)."""
        take = self.take(take_id)
        with self._lock:
            take.keep = bool(keep)
        return take

    def drop(self, take_id: int) -> None:
        """Delete the take and its files (a running take is stopped first)."""
        take = self.take(take_id)
        if take.running:
            self.stop_take(take_id)
        with self._lock:
            self._takes.pop(take_id, None)
        shutil.rmtree(take.folder, ignore_errors=True)

    # ---- build ---------------------------------------------------------------------------

    def build(self, name: str, *, tool: str = "pen", description: str = "",
              actuator: str = DEFAULT_ACTUATOR) -> BuildJob:
        """Build a profile from the kept takes on a thread and install it (see the module doc).

        Args:
            name: the pen's name (letters, digits, ``-_.``); an installed pen of that name
                (not a bundled one) is replaced.
            tool: the tool type (pencil, ballpoint, marker, …).
            description: a sentence about the pen.
            actuator: the pen's actuator as a model (``lra:f0=..,q=..``, ``piezo:…``,
                ``flat``); a measured response is built with ``realpen profile build``.

        Returns:
            The job; poll :meth:`job`.

        Raises:
            RecorderBusy: a take or another build runs.
            ParameterError: a bad name or actuator, a bundled pen's name.
            RealPenError: no kept take with samples.
        """
        from realpen.profile.build import check_name
        from realpen.tactile.actuator import parse_actuator

        check_name(name)
        held = self.catalog.get(name)
        if held is not None and held.where == "bundled":
            raise ParameterError("name", f"'{name}' is a bundled pen's name; choose another")
        if actuator.strip().partition(":")[0] not in ACTUATOR_MODELS:
            raise ParameterError("actuator", f"'{actuator}' is not a model "
                                             f"({', '.join(ACTUATOR_MODELS)}); build with a "
                                             f"measured response with realpen profile build")
        response = parse_actuator(actuator)
        with self._lock:
            if any(t.running for t in self._takes.values()):
                raise RecorderBusy("a take is running; stop it before building")
            if self._job is not None and self._job.state == "running":
                raise RecorderBusy("a profile is already being built")
            kept = [t for t in self._takes.values() if t.keep]
            vibration = max((t for t in kept if t.accel), key=lambda t: t.accel.seconds,
                            default=None)
            sound = max((t for t in kept if t.sound), key=lambda t: t.sound.seconds,
                        default=None)
            if vibration is None and sound is None:
                raise RealPenError("no kept take has an accelerometer or a microphone part; "
                                   "record a take (or keep one) first")
            job = BuildJob(self._next_job, name)
            self._next_job += 1
            self._job = job
        threading.Thread(target=self._build, args=(job, tool, description, response, vibration,
                                                   sound), name=f"build {name}",
                         daemon=True).start()
        return job

    def job(self) -> BuildJob | None:
        """The last build (running or finished), or None."""
        with self._lock:
            return self._job

    def _stage(self, job: BuildJob, stage: str, fraction: float) -> None:
        with self._lock:
            job.stage, job.fraction = stage, round(min(max(fraction, 0.0), 1.0), 3)

    def _build(self, job: BuildJob, tool: str, description: str, response, vibration_take,
               sound_take) -> None:
        try:
            profile = self._make_profile(job, tool, description, response, vibration_take,
                                         sound_take)
            self._stage(job, "installing", 0.95)
            from realpen.io.paths import user_profiles_dir
            from realpen.profile import save_profile

            folder = (self.profiles_dir or user_profiles_dir()) / job.name
            folder.parent.mkdir(parents=True, exist_ok=True)
            written = save_profile(profile, folder)
            self.catalog.add(Path(written))
            with self._lock:
                job.state, job.stage, job.fraction = "done", "installed", 1.0
                job.profile, job.summary = profile.name, profile.summary()
                job.notes = list(profile.meta.provenance.notes)
        except RealPenError as error:
            self._failed(job, " ".join(str(error).split()))
        except Exception as error:  # noqa: BLE001 - a bug: said on the page, the server goes on
            import logging

            logging.getLogger(__name__).exception("building %s", job.name)
            self._failed(job, f"internal error ({type(error).__name__}); see the server's log")

    def _failed(self, job: BuildJob, detail: str) -> None:
        with self._lock:
            job.state, job.detail = "failed", detail

    def _make_profile(self, job, tool, description, response, vibration_take, sound_take):
        from realpen.io.recording import load_recording
        from realpen.profile import build_profile
        from realpen.sound.loop import load_sound

        self._stage(job, "reading the takes", 0.02)
        vibration = load_recording(vibration_take.accel.path) if vibration_take else None
        sound = load_sound(sound_take.sound.path) if sound_take else None
        analysis = 0.8 if vibration is not None else 0.0

        def progress(done, total):
            self._stage(job, "analysing the vibration", 0.05 + analysis * done / max(total, 1))

        self._stage(job, "analysing the vibration" if vibration is not None
                    else "finding the sound's loop", 0.05)
        return build_profile(job.name, tool, vibration, sound, response,
                             description=description, progress=progress)

    def close(self) -> None:
        """Stop a running take and delete the session's files (a temporary folder)."""
        with self._lock:
            running = [t.id for t in self._takes.values() if t.running]
        for take_id in running:
            self.stop_take(take_id)
        if self._tmp is not None:
            self._tmp.cleanup()


def _check_sound(part: Path, target: Path, what: str) -> SoundPart:
    """Check an uploaded WAV and measure it; rename it to ``target`` when good."""
    import soundfile

    try:
        info = soundfile.info(str(part))
    except (RuntimeError, soundfile.LibsndfileError) as error:
        raise fail(what, f"not a readable WAV ({' '.join(str(error).split())})") from None
    if info.format != "WAV":
        raise fail(what, f"a {info.format} file, expected WAV")
    if info.subtype not in ("PCM_16", "FLOAT"):
        raise fail(what, f"{info.subtype} samples, expected 16-bit PCM or 32-bit float")
    if info.channels != 1:
        raise fail(what, f"{info.channels} channels, expected 1 (mono)")
    if info.samplerate not in SOUND_RATES:
        raise fail(what, f"{info.samplerate} Hz, expected "
                         f"{' or '.join(str(r) for r in SOUND_RATES)} Hz")
    if info.frames < 1:
        raise fail(what, "no samples")
    if info.frames > MAX_TAKE_S * info.samplerate:
        raise fail(what, f"{info.frames / info.samplerate:.1f} s, over the {MAX_TAKE_S:g} s a "
                         f"take may last")
    samples, rate = soundfile.read(str(part), dtype="float32", always_2d=False)
    if not np.all(np.isfinite(samples)):
        raise fail(what, "holds samples that are not numbers (NaN or infinite)")
    magnitude = np.abs(samples)
    rms = float(np.sqrt(np.mean(np.square(samples, dtype=np.float64))))
    part.replace(target)
    return SoundPart(target, round(len(samples) / rate, 3), int(rate), _db(rms),
                     _db(float(magnitude.max())), int(np.count_nonzero(magnitude >= MIC_CLIP)))
