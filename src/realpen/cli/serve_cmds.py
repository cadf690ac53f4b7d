"""``realpen serve`` (the live app) and ``realpen strokes export``."""

import ipaddress
import signal
from pathlib import Path

import typer

from realpen.checks import require_choice
from realpen.cli.common import check_outputs, command_group, console, force_option
from realpen.errors import ParameterError, RealPenError
from realpen.io.paths import default_store

__all__ = ["strokes_app", "serve", "register"]

TACTILE_CHOICES = ("audio", "none")
DEVICE_WAIT_S = 3.0  # how long the summary waits for the pen's first connection attempt
DEVICE_HELP = ("The pen's own device: sim (the simulated pen: the real firmware under the "
               "MicroPython Unix port on a pseudo-terminal, restarted if it exits), serial:PORT "
               "(a pen on USB, e.g. serial:/dev/ttyACM0; the port 'realpen device sim' prints "
               "is serial:/dev/pts/N) or ble:NAME (a pen over Bluetooth, by name or address). "
               "Pen down/up and gain become the pen protocol's SET_STATE and a change of pen "
               "uploads its pattern; a pen that goes away is reconnected. Default: no pen, the "
               "commands are only logged (/api/device/log).")
LAN_TOKEN_FILE = "lan-token"  # in the data folder: the LAN token a restarted server keeps
STORE_HELP = ("The store: an SQLite file (default: strokes.sqlite3 in the data folder) or a "
              "PostgreSQL URL, postgresql://USER:PASSWORD@HOST/DATABASE.")

strokes_app = command_group("The strokes the live app stored.")


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def serve(
    host: str | None = typer.Option(
        None, "--host", help="Address to listen on (default 127.0.0.1; with --lan 0.0.0.0)."),
    port: int = typer.Option(8765, "--port", help="Port to listen on (0: any free port)."),
    profiles: list[Path] = typer.Option(
        [], "--profiles", help="A folder of extra pen profiles (repeatable)."),
    store: str | None = typer.Option(None, "--store", metavar="FILE|URL", help=STORE_HELP),
    tactile: str = typer.Option(
        "none", "--tactile",
        help="audio: the tactile pattern plays on the right audio channel (sound on the left), "
             "for an actuator on an amplifier | none: touch only on the pen's own device."),
    lan: bool = typer.Option(
        False, "--lan", help="Listen on all interfaces for a tablet on the same network; every "
                             "request then needs the random token in the printed URL (kept in "
                             "the data folder, so a restarted server has the same)."),
    renew_token: bool = typer.Option(
        False, "--new-token", help="With --lan: make a new token (tablets must open the new "
                                   "URL)."),
    designs: list[Path] = typer.Option(
        [], "--design", help="A study design file (YAML or JSON) to offer beside study1 and "
                             "study2 (repeatable)."),
    device: str | None = typer.Option(None, "--device", metavar="sim|serial:PORT|ble:NAME",
                                      help=DEVICE_HELP),
) -> None:
    """Start the live app: open the printed URL, pick a pen, and write (studies: /study)."""
    from realpen.io.paths import data_dir
    from realpen.live.app import LiveSettings, create_app
    from realpen.live.auth import LOOPBACK_HOSTS, kept_token
    from realpen.live.device import open_device, parse_device
    from realpen.live.server import bind, lan_address, run, url_host
    from realpen.study.db import STORE_ERRORS, store_error

    require_choice("tactile", tactile, TACTILE_CHOICES)
    if device is not None:
        try:
            parse_device(device)
        except ParameterError as error:
            raise RealPenError(f"--device: {error.problem}") from None
    if renew_token and not lan:
        raise RealPenError("--new-token: only with --lan (without it no token is used)")
    host = host or ("0.0.0.0" if lan else "127.0.0.1")
    if not lan and not _is_loopback(host):
        raise RealPenError(f"--host {host}: other machines could reach it; add --lan (every "
                           f"request then needs a random token)")
    store = default_store() if store is None else store
    token = kept_token(data_dir() / LAN_TOKEN_FILE, renew=renew_token) if lan else None
    # The port first: a port in use is refused before the pen, the profiles and the store.
    sock = bind(host, port)
    pen = None
    try:
        pen = open_device(device)
        settings = LiveSettings(store=store, profiles=list(profiles), tactile=tactile,
                                token=token, allowed_hosts=None if lan else LOOPBACK_HOSTS,
                                designs=list(designs), device=pen)
        try:
            live_app = create_app(settings)
        except STORE_ERRORS as error:  # opening the store writes (ending strokes a kill left open)
            raise store_error(store, error) from None
    except BaseException:
        sock.close()
        if pen is not None:
            pen.close()
        raise
    state = live_app.state.live
    # uvicorn stops gracefully on SIGINT/SIGTERM, then re-raises the signal: end quietly.
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        port = sock.getsockname()[1]
        query = f"?token={token}" if token else ""
        shown = lan_address() if lan and host in ("0.0.0.0", "::") else host
        summary = [f"RealPen live: http://{url_host(shown)}:{port}/{query}"]
        if lan:
            summary.append(f"  (open it on the tablet; on this machine: "
                           f"http://127.0.0.1:{port}/{query})")
        summary.append(f"  studies: http://{url_host(shown)}:{port}/study{query} "
                       f"({', '.join(state.designs)})")
        summary.append(f"  pens: {', '.join(state.catalog.names)} | tactile: "
                       f"{'audio, right channel' if tactile == 'audio' else 'none (pen device)'}"
                       f" | store: {state.store.display}")
        # Profiles that did not load are said here, once, on stdout (not logged to stderr).
        summary += [f"  skipped profile: {problem}" for problem in state.catalog.skipped]
        summary.append(f"  pen device: {_device_line(pen)}")
        summary.append("  Ctrl-C stops the server.")
        print("\n".join(summary), flush=True)  # one write: a quick Ctrl-C cannot split it
        run(live_app, sock)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        sock.close()
        if not state.stopped:  # the app never shut down (it never started serving)
            state.store.discard()
            pen.close()
    if state.count_problem is not None:
        print(f"stopped: the store is closed but could not be counted ({state.count_problem}) "
              f"({state.store.display})", flush=True)
        return
    strokes, samples = state.final_counts or (0, 0)
    print(f"stopped: the store holds {strokes} strokes, {samples} samples "
          f"({state.store.display})", flush=True)


def _device_line(pen) -> str:
    """The summary's pen-device line: the device and its state after its first attempt."""
    from realpen.live.device import device_status

    wait = getattr(pen, "wait_attempted", None)
    if wait is not None:
        wait(DEVICE_WAIT_S)
    status = device_status(pen)
    if status["kind"] == "log":
        return "none (the commands are only logged: /api/device/log)"
    return f"{status['name']}: {status['message']}"


@strokes_app.command("export")
def export(
    output: Path = typer.Option(..., "-o", "--output", help="CSV to write, one row per sample."),
    store: str | None = typer.Option(None, "--store", metavar="FILE|URL", help=STORE_HELP),
    stroke: int | None = typer.Option(
        None, "--stroke", help="Only this stroke (its id in the store): a trajectory for "
                               "`realpen sound render`."),
    include_pilot: bool = typer.Option(
        False, "--include-pilot", help="Also the strokes of pilot study sessions (left out "
                                       "by default, as `realpen study export` leaves them out)."),
    force: bool = force_option(),
) -> None:
    """Write the stored strokes as CSV: stroke, page, pen, modality, …, t, x, y, pressure, tilt, speed."""
    from realpen.live.store import export_csv
    from realpen.study.db import hide_password, store_file

    store = default_store() if store is None else store
    file = store_file(store)
    # An SQLite store's journal files are part of it: writing over one would lose what it holds.
    check_outputs(output, force=force, inputs={} if file is None else {
        "stroke store": file, **{f"stroke store's {suffix} file": Path(f"{file}{suffix}")
                                 for suffix in ("-wal", "-shm", "-journal")}})
    strokes, rows = export_csv(store, output, stroke, include_pilot)
    console.print(f"wrote {output}: {rows} samples of {strokes} strokes from "
                  f"{hide_password(store)}", highlight=False)


def register(app: typer.Typer) -> None:
    """Add ``realpen strokes`` and ``realpen serve`` to the root command."""
    app.add_typer(strokes_app, name="strokes")
    app.command()(serve)
