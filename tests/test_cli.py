"""The command line as people expect it: --version, -h, ``python -m realpen``, help without the
heavy imports, one flag map, no silent replacement of outputs, and ``profile build --install``.

Everything runs in-process through :func:`conftest.run_cli`, except two subprocesses: ``python
-m realpen --help`` and a fresh interpreter that checks what importing the CLI loads.
"""

from __future__ import annotations

import json
import re

import pytest
from conftest import assert_clean_failure, run_cli, run_cli_process

import realpen
from realpen.cli.flags import COMMAND_FLAGS, DEFAULT_FLAGS, flag_for


def leaf_commands() -> dict:
    """Every runnable command by its path (``"sound loop"``), as click objects."""
    import typer.main

    from realpen.cli import app

    def walk(command, path):
        if hasattr(command, "commands"):
            for name, sub in command.commands.items():
                yield from walk(sub, [*path, name])
        else:
            yield " ".join(path), command

    return dict(walk(typer.main.get_command(app), []))


def flags_of(command) -> set[str]:
    return {flag for param in command.params for flag in (*param.opts, *param.secondary_opts)}


# --- --version, -h, python -m realpen --------------------------------------------------------

def test_version_prints_the_package_version():
    result = run_cli("--version")
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"realpen {realpen.__version__}\n"
    assert re.fullmatch(r"realpen \d+\.\d+\.\d+\S*", result.stdout.strip())


@pytest.mark.parametrize("path", ["", "analyze", "tactile", "tactile build", "tactile render",
                                  "sound", "sound loop", "sound render",
                                  "sound fit", "profile", "profile build", "export", "serve",
                                  "strokes export", "hatt", "hatt list", "hatt synth"])
def test_dash_h_is_help_everywhere(path):
    short, long = run_cli(*path.split(), "-h"), run_cli(*path.split(), "--help")
    assert short.returncode == 0 == long.returncode, short.stderr
    assert "Usage: realpen" in short.stdout and short.stdout == long.stdout


@pytest.mark.slow
def test_python_dash_m_realpen_prints_usage():
    done = run_cli_process("--help")
    assert done.returncode == 0, done.stderr
    assert "Usage: realpen" in done.stdout and "hatt" in done.stdout and "--version" in done.stdout


@pytest.mark.slow
def test_the_help_reads_the_library_constants_without_numpy():
    """The commands' defaults come from the library's numpy-free modules (realpen.defaults,
    realpen.checks), not from copies; importing the command modules loads no numpy."""
    import subprocess
    import sys

    modules = ", ".join(f"realpen.cli.{name}" for name in ("sound_cmds", "tactile_cmds",
                                                           "export_cmds", "device_cmds"))
    code = f"import sys, {modules}; print(sorted(m for m in ('numpy', 'scipy') if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_tactile_option_defaults_agree_with_the_library():
    """analyze, tactile and profile build write TactileParams' defaults (condition B) out,
    except the model: the command line builds with the recommended one."""
    from realpen.tactile.build import DEFAULT_ACTUATOR
    from realpen.tactile.conditions import RECOMMENDED_MODEL, TactileParams

    library = TactileParams(model=RECOMMENDED_MODEL)
    commands = leaf_commands()
    for path in ("analyze", "tactile build", "profile build"):
        for param in commands[path].params:
            name = "selection" if param.name == "select" else param.name
            if param.default is not None and hasattr(library, name):
                assert param.default == getattr(library, name), (path, param.name)
        if path != "analyze":
            assert next(p.default for p in commands[path].params if p.name == "actuator") \
                == DEFAULT_ACTUATOR, path


# --- the one flag map ------------------------------------------------------------------------

def test_every_mapped_flag_exists_on_a_command():
    commands = leaf_commands()
    everywhere = set().union(*(flags_of(c) for c in commands.values()))
    assert set(DEFAULT_FLAGS.values()) <= everywhere, set(DEFAULT_FLAGS.values()) - everywhere
    for path, overrides in COMMAND_FLAGS.items():
        assert set(overrides.values()) <= flags_of(commands[path]), path


def test_an_option_named_like_a_library_parameter_maps_to_its_own_flag():
    """Where a command's option has a library parameter's name, the map gives that option's
    flag: a ParameterError about it shows the flag the user typed."""
    for path, command in leaf_commands().items():
        for param in command.params:
            if param.param_type_name != "option":
                continue
            flag = flag_for(path, param.name)
            if flag != param.name:
                assert flag in (*param.opts, *param.secondary_opts), (path, param.name, flag)


def test_qualified_keys_tell_apart_two_parameters_of_one_name():
    assert flag_for("tactile build", "rate", ["_load_csv", "load_recording", "tactile"]) \
        == "--input-rate"
    assert flag_for("tactile build", "rate", ["build_pattern", "tactile"]) == "--rate"
    assert flag_for("profile build", "unit_ms", ["find_loop_unit", "build_profile"]) \
        == "--sound-unit-ms"
    assert flag_for("profile build", "unit_ms", ["analyze", "build_pattern", "build_profile"]) \
        == "--unit-ms"
    assert flag_for("analyze", "count") == "--subpatterns"
    assert flag_for("sound render", "find_unit") == "--as-loop"
    assert flag_for("analyze", "no_such_parameter") == "no_such_parameter"


# --- no silent replacement -------------------------------------------------------------------

def test_sound_commands_refuse_existing_outputs_unless_forced(tmp_path):
    measurements = tmp_path / "m.csv"
    rows = [f"{p:.2f},{v:.1f},{0.9 * (p - 0.2) + 0.012 * (v - 8):.5f}"
            for p in (0.3, 0.5, 0.7, 0.9) for v in (20.0, 60.0, 100.0, 140.0)]
    measurements.write_text("pressure,speed,amplitude\n" + "\n".join(rows) + "\n")
    out, report = tmp_path / "coupling.json", tmp_path / "fit.json"
    report.write_text("{}")
    result = run_cli("sound", "fit", measurements, "-o", out, "--json", report)
    assert_clean_failure(result, f"realpen: error: {report}: exists; pass --force to replace it")
    assert not out.exists() and report.read_text() == "{}"
    result = run_cli("sound", "fit", measurements, "-o", out, "--json", report, "--force")
    assert result.returncode == 0, result.stderr
    assert json.loads(report.read_text())["rows"] == 16
    # Refused before the (missing) recording is read.
    result = run_cli("sound", "loop", tmp_path / "missing.wav", "-o", out)
    assert_clean_failure(result, f"{out}: exists; pass --force to replace it")
    result = run_cli("sound", "render", "--sound", tmp_path / "missing.wav", "--trajectory",
                     measurements, "-o", out)
    assert_clean_failure(result, f"{out}: exists; pass --force to replace it")
    result = run_cli("sound", "fit", measurements, "-o", measurements, "--force")
    assert_clean_failure(result, "would replace the measurements itself")


def test_export_refuses_an_existing_output_or_companion_unless_forced(tmp_path):
    out = tmp_path / "pen.ahap"
    assert run_cli("export", "pencil", "--format", "ahap", "-o", out).returncode == 0
    companion = tmp_path / "pen-sound.wav"
    assert companion.exists()
    before = out.read_bytes()
    out.write_text("mine")
    result = run_cli("export", "pencil", "--format", "ahap", "-o", out)
    assert_clean_failure(result, f"{out}: exists; pass --force to replace it")
    assert out.read_text() == "mine"
    out.unlink()
    result = run_cli("export", "pencil", "--format", "ahap", "-o", out)  # the sound is still there
    assert_clean_failure(result, f"{companion}: exists; pass --force to replace it")
    assert not out.exists()
    result = run_cli("export", "pencil", "--format", "ahap", "-o", out, "--force")
    assert result.returncode == 0, result.stderr
    assert out.read_bytes() == before


# --- profile build: where the profile went, --install ----------------------------------------

@pytest.fixture
def recordings(tmp_path):
    from realpen.pens.build import write_model_recordings

    return write_model_recordings("pencil", tmp_path)


def test_profile_build_says_where_and_install_puts_it_in_the_profiles_folder(
        tmp_path, recordings, monkeypatch):
    vibration, sound = recordings
    home = tmp_path / "home"
    monkeypatch.setenv("REALPEN_HOME", str(home))
    monkeypatch.chdir(tmp_path)
    common = ["profile", "build", "--name", "mine", "--vibration", vibration, "--sound", sound]
    result = run_cli(*common, "-o", "bundle")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"wrote {(tmp_path / 'bundle').resolve()}: ")
    result = run_cli(*common, "-o", "bundle")
    assert_clean_failure(result, "bundle: exists; pass --force to replace it")
    assert run_cli(*common, "-o", "bundle", "--force").returncode == 0
    installed = home / "profiles" / "mine"
    result = run_cli(*common, "--install")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"wrote {installed.resolve()}: ")
    assert (installed / "profile.json").exists()
    listing = run_cli("profile", "list")
    assert listing.returncode == 0 and "mine" in listing.stdout
    assert_clean_failure(run_cli(*common, "--install"), f"{installed}: exists; pass --force")
    assert_clean_failure(run_cli(*common, "--install", "-o", "x"), "either -o/--output or --install")
    assert_clean_failure(run_cli(*common), "either -o/--output or --install")
    # One name, two parameters: the tactile unit and the sound's loop unit.
    result = run_cli(*common, "-o", "other", "--sound-unit-ms", "0")
    assert_clean_failure(result, "realpen: error: --sound-unit-ms: ")
    result = run_cli(*common, "-o", "other", "--unit-ms", "0", "--top", "5", "--subpatterns", "15")
    assert_clean_failure(result, "realpen: error: --unit-ms: ")
    result = run_cli("profile", "build", "--name", "../up", "--vibration", vibration, "--sound",
                     sound, "--install")
    assert_clean_failure(result, "realpen: error: --name: '../up' is not a valid profile name")
    assert sorted(p.name for p in (home / "profiles").iterdir()) == ["mine"]


def test_check_outputs_sees_an_input_through_links_and_inside_folders(tmp_path):
    from realpen.cli.common import check_outputs, same_file
    from realpen.errors import RealPenError

    source = tmp_path / "rec.wav"
    source.write_bytes(b"RIFF")
    (tmp_path / "hard.wav").hardlink_to(source)
    (tmp_path / "soft.wav").symlink_to(source.name)
    assert same_file(tmp_path / "hard.wav", source) and same_file(tmp_path / "soft.wav", source)
    assert not same_file(tmp_path / "new.wav", source)
    for name in ("hard.wav", "soft.wav", "./rec.wav"):
        with pytest.raises(RealPenError, match="would replace the recording itself"):
            check_outputs(tmp_path / name, force=True, inputs={"recording": source})
    bundle = tmp_path / "bundle"
    bundle.mkdir()
    with pytest.raises(RealPenError, match=r"new\.wav: lies inside the profile .*bundle"):
        check_outputs(bundle / "sub" / "new.wav", force=True, inputs={"profile": bundle})
    with pytest.raises(RealPenError, match="given for two outputs"):
        check_outputs(tmp_path / "a.wav", tmp_path / "x" / ".." / "a.wav", force=True)
    check_outputs(tmp_path / "new.wav", tmp_path / "other.wav", force=False,
                  inputs={"recording": source, "profile": bundle})  # nothing in the way


@pytest.mark.parametrize("digits", [20, 400])
def test_integer_options_refuse_numbers_beyond_64_bits(digits):
    result = run_cli("analyze", "missing.wav", "--top", "9" * digits)
    assert_clean_failure(result, f"Invalid value for '--top': a {digits}-digit number is too "
                                 f"large")
    from realpen.examples import example_recording_path

    # The largest 64-bit number reaches the library, whose limit names the flag.
    result = run_cli("analyze", example_recording_path(), "--top", str(2 ** 63 - 1))
    assert_clean_failure(result, "--top: must be <= 100, got 9223372036854775807")
