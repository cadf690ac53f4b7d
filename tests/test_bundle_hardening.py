"""Hardened profile bundles: whatever a bundle's bytes, loading it either works or raises one
:class:`RealPenError` line naming it, within bounded memory; a bad bundle is skipped with one
warning by ``profile list`` and ``serve``, and everything else still works.

Every malformed bundle is made at test time from the bundled pencil. Two tests run a fresh
interpreter: the zip bombs under an address-space limit, and a real ``realpen serve``.
"""

from __future__ import annotations

import copy
import io
import json
import os
import random
import resource
import struct
import subprocess
import sys
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from conftest import assert_clean_failure, run_cli
from live_support import serve

from realpen.errors import ParameterError, RealPenError
from realpen.io.files import wav_bytes
from realpen.io.limits import MAX_JSON_BYTES, MAX_JSON_DEPTH, MAX_NUMBER_CHARS
from realpen.live.catalog import Catalog, CatalogEntry
from realpen.pens import BUNDLED_PENS
from realpen.profile import resolve_profile, save_profile
from realpen.profile.bundle import MAX_ZIP_BYTES, MAX_ZIP_ENTRIES, PenProfile
from realpen.profile.registry import load_profile
from realpen.profile.schema import MAX_WAV_BYTES, MAX_WAV_FRAMES

GiB = 2**30
MiB = 2**20
# The address space the bomb tests allow a fresh `realpen` (bytes): the good call needs a few
# hundred MB; inflating the 2 GiB WAV or the 1 GiB profile.json, as RealPen once did, cannot fit.
ADDRESS_LIMIT = 2 * GiB
WARNING = "realpen: warning: skipped profile "


@pytest.fixture(scope="module")
def pencil() -> PenProfile:
    return resolve_profile("pencil")


@pytest.fixture
def good(pencil, tmp_path) -> Path:
    """A good folder bundle of the pencil, to damage."""
    return save_profile(pencil, tmp_path / "pen")


# --- building damaged bundles ----------------------------------------------------------------

def read_document(folder: Path) -> dict:
    return json.loads((folder / "profile.json").read_text())


def write_document(folder: Path, document: dict | str | bytes) -> Path:
    if isinstance(document, dict):
        document = json.dumps(document)
    if isinstance(document, str):
        document = document.encode()
    (folder / "profile.json").write_bytes(document)
    return folder


def replace_wav(folder: Path, name: str, data: bytes) -> Path:
    """Put ``data`` in as ``name`` and make profile.json's SHA-256 agree, so the checks after the
    hash are the ones that must refuse it."""
    import hashlib

    (folder / name).write_bytes(data)
    document = read_document(folder)
    document["files"][name.removesuffix(".wav")]["sha256"] = hashlib.sha256(data).hexdigest()
    return write_document(folder, document)


def zip_of(folder: Path, target: Path, extra: dict[str, bytes] | None = None) -> Path:
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in sorted(folder.iterdir()):
            archive.write(file, file.name)
        for name, data in (extra or {}).items():
            archive.writestr(name, data)
    return target


def wav_header(data_bytes: int, rate: int = 8000) -> bytes:
    """The 44-byte header of a mono 32-bit float WAV whose data chunk says ``data_bytes``."""
    fmt = struct.pack("<HHIIHH", 3, 1, rate, rate * 4, 4, 32)
    return (b"RIFF" + struct.pack("<I", 36 + data_bytes) + b"WAVE" + b"fmt " + struct.pack("<I", 16)
            + fmt + b"data" + struct.pack("<I", data_bytes))


def deflate_repeated(head: bytes, chunk: bytes, count: int) -> tuple[bytes, int, int]:
    """A raw deflate stream of ``head + chunk * count``, made without compressing it all.

    Each part is compressed on its own and ended with a full flush (byte-aligned, referring to
    nothing before it), so the compressed chunk can be repeated; an empty final block closes
    the stream. Returns (stream, CRC-32, inflated size in bytes).
    """
    def flushed(data: bytes) -> bytes:
        compressor = zlib.compressobj(9, zlib.DEFLATED, -15)
        return compressor.compress(data) + compressor.flush(zlib.Z_FULL_FLUSH)

    stream = flushed(head) + flushed(chunk) * count + b"\x03\x00"
    crc = zlib.crc32(head)
    for _ in range(count):
        crc = zlib.crc32(chunk, crc)
    return stream, crc, len(head) + len(chunk) * count


def handmade_zip(target: Path, entries: list[tuple[str, bytes, int, int, int, int]]) -> Path:
    """Write a zip by hand, so that its headers may say what zipfile would never write.

    Args:
        entries: (name, bytes as stored, CRC-32, declared inflated size, method, flag bits).
    """
    local, central = bytearray(), bytearray()
    for name, stored, crc, size, method, flags in entries:
        encoded = name.encode()
        offset = len(local)
        # version 20, date 1980-01-01 (0x21), no extra field
        local += struct.pack("<4s5H3L2H", b"PK\x03\x04", 20, flags, method, 0, 0x21, crc,
                             len(stored), size, len(encoded), 0) + encoded + stored
        central += struct.pack("<4s6H3L5H2L", b"PK\x01\x02", 20, 20, flags, method, 0, 0x21, crc,
                               len(stored), size, len(encoded), 0, 0, 0, 0, 0, offset) + encoded
    end = struct.pack("<4s4H2LH", b"PK\x05\x06", 0, 0, len(entries), len(entries), len(central),
                      len(local), 0)
    target.write_bytes(bytes(local + central + end))
    return target


def stored_entries(folder: Path, **replaced) -> list[tuple[str, bytes, int, int, int, int]]:
    """The bundle's files as stored zip entries; ``replaced`` maps a file (``tactile_wav``) to
    the entry to use instead."""
    entries = []
    for name in ("profile.json", "tactile.wav", "sound.wav"):
        data = (folder / name).read_bytes()
        entries.append(replaced.get(name.replace(".", "_"),
                                    (name, data, zlib.crc32(data), len(data), 0, 0)))
    return entries


def wav_bomb(folder: Path, target: Path, gib: int = 2) -> Path:
    """A zip of the bundle whose tactile.wav is a float WAV header and ``gib`` GiB of zeros
    (about 1 MB per GiB on disk)."""
    stream, crc, size = deflate_repeated(wav_header(gib * GiB), bytes(MiB), gib * 1024)
    return handmade_zip(target, stored_entries(
        folder, tactile_wav=("tactile.wav", stream, crc, size, zipfile.ZIP_DEFLATED, 0)))


def whitespace_bomb(folder: Path, target: Path, mib: int = 1024) -> Path:
    """A zip of the bundle whose profile.json is the good document and ``mib`` MiB of spaces:
    valid JSON, once parsed."""
    document = (folder / "profile.json").read_bytes()
    stream, crc, size = deflate_repeated(document, b" " * MiB, mib)
    return handmade_zip(target, stored_entries(
        folder, profile_json=("profile.json", stream, crc, size, zipfile.ZIP_DEFLATED, 0)))


def sparse(path: Path, size: int) -> None:
    """Make ``path`` a file of ``size`` bytes that takes no room on disk."""
    path.unlink(missing_ok=True)
    with open(path, "wb") as handle:
        handle.truncate(size)


# --- the corpus: each damages a good bundle, returns (bundle, text the error must hold) --------

def zip_encrypted(good: Path, tmp: Path):
    data = (good / "tactile.wav").read_bytes()
    # Flag bit 0: encrypted. zipfile itself would raise RuntimeError on reading it.
    entry = ("tactile.wav", data, zlib.crc32(data), len(data), 0, 0x1)
    return handmade_zip(tmp / "encrypted.zip", stored_entries(good, tactile_wav=entry)), \
        "tactile.wav is encrypted"


def zip_unknown_method(good: Path, tmp: Path):
    data = (good / "sound.wav").read_bytes()
    # Method 99 (AES in WinZip's scheme): zipfile would raise NotImplementedError.
    entry = ("sound.wav", data, zlib.crc32(data), len(data), 99, 0)
    return handmade_zip(tmp / "method.zip", stored_entries(good, sound_wav=entry)), \
        "compression method 99"


def zip_lzma(good: Path, tmp: Path):
    archive = tmp / "lzma.zip"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_LZMA) as handle:
        for file in sorted(good.iterdir()):
            handle.write(file, file.name)
    return archive, "compression method 14"


def zip_too_many_entries(good: Path, tmp: Path):
    padding = {f"padding/{i}.txt": b"" for i in range(MAX_ZIP_ENTRIES)}
    return zip_of(good, tmp / "many.zip", padding), f"holds {MAX_ZIP_ENTRIES + 3} entries"


def zip_declared_too_big(good: Path, tmp: Path):
    # 80 MiB of WAV in 80 kB: over the limit as declared, refused before any byte is inflated.
    stream, crc, size = deflate_repeated(wav_header(80 * MiB), bytes(MiB), 80)
    entry = ("tactile.wav", stream, crc, size, zipfile.ZIP_DEFLATED, 0)
    return handmade_zip(tmp / "big.zip", stored_entries(good, tactile_wav=entry)), \
        f"tactile.wav is declared {size:,} bytes; the limit is {MAX_WAV_BYTES:,}"


def zip_lying_size(good: Path, tmp: Path):
    # Declares the real WAV's size and CRC, but its stream inflates to 64 MiB: reading stops at
    # the declared size, where the CRC no longer matches.
    data = (good / "tactile.wav").read_bytes()
    stream, _, _ = deflate_repeated(wav_header(64 * MiB), bytes(MiB), 64)
    entry = ("tactile.wav", stream, zlib.crc32(data), len(data), zipfile.ZIP_DEFLATED, 0)
    return handmade_zip(tmp / "lying.zip", stored_entries(good, tactile_wav=entry)), \
        "not a profile folder or a readable .zip (Bad CRC-32"


def zip_whitespace_json(good: Path, tmp: Path):
    return whitespace_bomb(good, tmp / "spaces.zip", mib=8), \
        f"profile.json is declared {(good / 'profile.json').stat().st_size + 8 * MiB:,} bytes"


def zip_truncated(good: Path, tmp: Path):
    whole = zip_of(good, tmp / "whole.zip").read_bytes()
    target = tmp / "truncated.zip"
    target.write_bytes(whole[:len(whole) // 2])
    return target, "not a profile folder or a readable .zip"


def zip_oversized(good: Path, tmp: Path):
    target = tmp / "huge.zip"
    sparse(target, MAX_ZIP_BYTES + 1)
    return target, f"a profile .zip is limited to {MAX_ZIP_BYTES:,}"


def zip_fifo(good: Path, tmp: Path):
    target = tmp / "pipe.zip"
    os.mkfifo(target)  # opening it for reading would wait for a writer forever
    return target, "is not a regular file"


def json_deep(good: Path, tmp: Path):
    document = read_document(good)
    text = json.dumps(document).replace('"description": ', '"description": ' + "[" * 5000, 1)
    return write_document(good, text + "]" * 5000), "levels deep; the limit is " \
        f"{MAX_JSON_DEPTH}"


def json_long_number(good: Path, tmp: Path):
    document = read_document(good)
    document["sound"]["frames"] = 0
    text = json.dumps(document).replace('"frames": 0', '"frames": ' + "9" * 5000)
    return write_document(good, text), f"number longer than {MAX_NUMBER_CHARS} characters"


def json_seam_text(good: Path, tmp: Path):
    document = read_document(good)
    document["sound"]["seam"]["level_jump_db"] = "loud"
    return write_document(good, document), \
        "sound.seam.level_jump_db: must be a finite number, got str"


def json_rate_out_of_range(good: Path, tmp: Path):
    document = read_document(good)
    document["sound"]["rate"] = 10**9
    return write_document(good, document), "sound.rate: Input should be less than or equal"


def json_frames_over_limit(good: Path, tmp: Path):
    document = read_document(good)
    document["files"]["tactile"]["frames"] = MAX_WAV_FRAMES + 1
    return write_document(good, document), "files.tactile.frames"


def json_overflowing_float(good: Path, tmp: Path):
    document = read_document(good)
    document["coupling"]["c_p"] = "OVERFLOW"
    text = json.dumps(document).replace('"OVERFLOW"', "1e999")  # parsed as inf
    return write_document(good, text), "coupling: c_p"


def json_not_an_object(good: Path, tmp: Path):
    return write_document(good, "[1, 2]"), "profile.json must hold a JSON object"


def json_not_utf8(good: Path, tmp: Path):
    return write_document(good, b'{"name": "\xff"}'), "is not UTF-8"


def json_long_unknown_key(good: Path, tmp: Path):
    document = read_document(good)
    document["x" * 1_000_000] = 1
    return write_document(good, document), "Extra inputs are not permitted"


def json_format_junk(good: Path, tmp: Path):
    document = read_document(good)
    document["format"] = "2\n" + "y" * 100_000
    return write_document(good, document), "unknown profile format"


def wav_header_claims_more(good: Path, tmp: Path):
    data = (good / "tactile.wav").read_bytes()
    # The data chunk says 2 GiB; the file holds 48 kB.
    forged = data.replace(b"data" + data[data.index(b"data") + 4:data.index(b"data") + 8],
                          b"data" + struct.pack("<I", 2 * GiB), 1)
    return replace_wav(good, "tactile.wav", forged), "tactile.wav is"


def wav_longer_than_the_profile(good: Path, tmp: Path):
    longer = wav_bytes(np.zeros(400_000, dtype=np.float32), 8000)
    return replace_wav(good, "tactile.wav", longer), \
        "tactile.wav is 400000 frames at 8000 Hz; profile.json says 12000 frames at 8000 Hz"


def wav_stereo(good: Path, tmp: Path):
    stereo = wav_bytes(np.zeros((12000, 2), dtype=np.float32), 8000)
    return replace_wav(good, "tactile.wav", stereo), "tactile.wav has 2 channels"


def folder_huge_wav(good: Path, tmp: Path):
    sparse(good / "tactile.wav", 3 * GiB)
    return good, f"tactile.wav is {3 * GiB:,} bytes; the limit is {MAX_WAV_BYTES:,}"


def folder_huge_json(good: Path, tmp: Path):
    sparse(good / "profile.json", GiB)
    return good, f"profile.json is {GiB:,} bytes; the limit is {MAX_JSON_BYTES:,}"


def folder_symlink(good: Path, tmp: Path):
    (good / "tactile.wav").unlink()
    (good / "tactile.wav").symlink_to("/dev/zero")
    return good, "tactile.wav is a symbolic link"


def folder_fifo(good: Path, tmp: Path):
    (good / "sound.wav").unlink()
    os.mkfifo(good / "sound.wav")
    return good, "sound.wav is not a regular file"


def folder_member_is_a_folder(good: Path, tmp: Path):
    (good / "profile.json").unlink()
    (good / "profile.json").mkdir()
    return good, "profile.json is not a regular file"


CORPUS: dict[str, Callable[[Path, Path], tuple[Path, str]]] = {
    case.__name__: case for case in (
        zip_encrypted, zip_unknown_method, zip_lzma, zip_too_many_entries, zip_declared_too_big,
        zip_lying_size, zip_whitespace_json, zip_truncated, zip_oversized, zip_fifo, json_deep,
        json_long_number, json_seam_text, json_rate_out_of_range, json_frames_over_limit,
        json_overflowing_float, json_not_an_object, json_not_utf8, json_long_unknown_key,
        json_format_junk, wav_header_claims_more, wav_longer_than_the_profile, wav_stereo,
        folder_huge_wav, folder_huge_json, folder_symlink, folder_fifo,
        folder_member_is_a_folder)}


def assert_one_line_naming(error: RealPenError, bundle: Path, expected: str) -> None:
    message = str(error)
    assert type(error) is RealPenError, type(error)
    assert message.startswith(f"{bundle}: "), message[:300]
    assert expected in message, message[:300]
    assert "\n" not in message and len(message) < len(str(bundle)) + 400, message[:300]


@pytest.mark.parametrize("case", list(CORPUS))
def test_every_malformed_bundle_is_refused_in_one_line_naming_it(good, tmp_path, case):
    bundle, expected = CORPUS[case](good, tmp_path)
    with pytest.raises(RealPenError) as info:
        load_profile(bundle)
    assert_one_line_naming(info.value, bundle, expected)


def test_the_corpus_starts_from_a_bundle_that_loads(good, tmp_path, pencil):
    """Each case damages one thing: the same bundle, undamaged, loads as a folder and a zip."""
    assert load_profile(good).version == pencil.version
    assert load_profile(zip_of(good, tmp_path / "pen.zip")).version == pencil.version
    entries = stored_entries(good)
    assert load_profile(handmade_zip(tmp_path / "hand.zip", entries)).version == pencil.version
    # The bombs' streams are real: a small one inflates to what its header says.
    stream, crc, size = deflate_repeated(b"head", b"\0" * 1000, 3)
    inflated = zlib.decompress(stream, -15)
    assert len(inflated) == size == 3004 and zlib.crc32(inflated) == crc


def test_a_newline_in_a_bundles_name_still_gives_one_line(good, tmp_path):
    odd = tmp_path / "two\nlines"
    good.rename(odd)
    json_seam_text(odd, tmp_path)
    with pytest.raises(RealPenError) as info:
        load_profile(odd)
    assert "\n" not in str(info.value) and "two lines" in str(info.value)


def test_random_damage_to_a_zip_gives_only_realpen_errors(good, tmp_path):
    """300 bundles with bytes overwritten or cut (seeded): each loads or is refused in one line
    naming it; most are refused."""
    rng = random.Random(2016)
    sources = [zip_of(good, tmp_path / "deflated.zip").read_bytes(),
               handmade_zip(tmp_path / "stored.zip", stored_entries(good)).read_bytes()]
    target = tmp_path / "damaged.zip"
    refused = 0
    for attempt in range(300):
        data = bytearray(sources[attempt % 2])
        if attempt % 3 == 0:
            data = data[:rng.randrange(len(data))]
        else:
            # Headers at both ends matter most: the local header and the central directory.
            for _ in range(rng.randint(1, 6)):
                where = rng.choice([rng.randrange(64), len(data) - 1 - rng.randrange(300),
                                    rng.randrange(len(data))])
                data[where] = rng.randrange(256)
        target.write_bytes(bytes(data))
        try:
            load_profile(target)
        except RealPenError as error:
            refused += 1
            assert_one_line_naming(error, target, "")
    assert refused > 250, refused


def small_pencil(pencil: PenProfile) -> PenProfile:
    """The pencil cut to 2 sub-patterns, so that loading it hundreds of times is quick."""
    import dataclasses

    pattern = dataclasses.replace(pencil.meta.tactile, subpatterns=pencil.meta.tactile.subpatterns[:2])
    meta = pencil.meta.model_copy(update={"tactile": pattern})
    return PenProfile(meta, pencil.tactile[:pattern.frames], pencil.sound)


def leaves(node, prefix=()):
    """Every position in a JSON document (the first two items of a list)."""
    yield prefix
    items = node.items() if isinstance(node, dict) else enumerate(node[:2]) \
        if isinstance(node, list) else ()
    for key, value in items:
        yield from leaves(value, (*prefix, key))


JUNK = ["x", -1, 0, 10**60, -1e308, None, [], {"a": [None]}, True]


@pytest.mark.slow
def test_junk_anywhere_in_profile_json_gives_only_realpen_errors(pencil, tmp_path):
    """Every value of profile.json in turn replaced by junk of each kind: the bundle is refused
    in one line, or it loads and everything the CLI and the server do with it works."""
    folder = save_profile(small_pencil(pencil), tmp_path / "small")
    original = read_document(folder)
    refused, loaded = set(), 0
    for where in list(leaves(original))[1:]:
        for junk in JUNK:
            document = copy.deepcopy(original)
            parent = document
            for key in where[:-1]:
                parent = parent[key]
            parent[where[-1]] = junk
            write_document(folder, document)
            try:
                profile = load_profile(folder)
            except RealPenError as error:
                assert_one_line_naming(error, folder, "")
                refused.add(".".join(map(str, where)))
                continue
            loaded += 1
            # What `profile show`, the exports and `serve` read of a profile.
            seen = (profile.summary(), repr(profile), profile.version, profile.pattern,
                    profile.sound_loop)
            assert all(seen)
            entry = CatalogEntry(profile, "extra")
            entry.check()
            entry.to_json()
            f"{profile.meta.sound.seam.get('level_jump_db', 0.0):.2f}"
    assert {"sound.seam.level_jump_db", "sound.rate", "files.tactile.frames", "coupling.c_p",
            "tactile.subpatterns.0.0.frequency_hz", "actuator.params.q"} <= refused
    assert loaded > 0  # free-form fields (provenance, description) take any JSON


def test_save_refuses_what_load_would_refuse(pencil, tmp_path):
    long = np.zeros(MAX_WAV_FRAMES + 1, dtype=np.float32)
    section = pencil.meta.sound.model_copy(update={"frames": len(long)})
    too_long = PenProfile(pencil.meta.model_copy(update={"sound": section}), pencil.tactile, long)
    with pytest.raises(ParameterError, match=f"files.sound.frames: .*{MAX_WAV_FRAMES}"):
        save_profile(too_long, tmp_path / "long")
    assert not (tmp_path / "long").exists()


# --- the command line and the catalogue ------------------------------------------------------

def fountain(pencil: PenProfile, folder: Path) -> Path:
    """A good profile other than the bundled ones."""
    profile = PenProfile(pencil.meta.model_copy(update={"name": "fountain", "tool": "fountain pen"}),
                         pencil.tactile, pencil.sound)
    return save_profile(profile, folder / "fountain")


def bad_bundles(pencil: PenProfile, folder: Path, cases: tuple[str, ...]) -> list[Path]:
    """The corpus ``cases``, each moved into ``folder`` under its case's name."""
    folder.mkdir(parents=True, exist_ok=True)
    made = []
    for case in cases:
        work = folder.parent / f"work-{case}"
        work.mkdir()
        bundle, _ = CORPUS[case](save_profile(pencil, work / "pen"), work)
        target = folder / (f"{case}.zip" if bundle.suffix == ".zip" else case)
        bundle.rename(target)
        made.append(target)
    return made


LISTED_CASES = ("zip_encrypted", "json_deep", "json_seam_text", "folder_symlink", "zip_fifo")


def test_profile_list_warns_once_per_bad_bundle_and_lists_the_rest(pencil, tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    extra = tmp_path / "pens"
    fountain(pencil, extra)
    bad = bad_bundles(pencil, extra, LISTED_CASES)
    # One more in the user's own profiles folder, found by name too.
    user = bad_bundles(pencil, tmp_path / "home" / "profiles", ("json_long_number",))
    result = run_cli("profile", "list", "--profiles", extra)
    assert result.returncode == 0, result.stderr
    listed = result.stdout.splitlines()
    assert [line.split(":")[0] for line in listed] == [*sorted(BUNDLED_PENS), "fountain"]
    warnings = result.stderr.splitlines()
    assert len(warnings) == len(bad) + 1, result.stderr
    for bundle in (*user, *bad):
        lines = [line for line in warnings if line.startswith(f"{WARNING}{bundle}: ")]
        assert len(lines) == 1, (bundle, result.stderr)
    assert "Traceback" not in result.stderr
    # A folder of profiles asked for by name that is not one is an error, not a warning.
    not_a_folder = fountain(pencil, tmp_path / "other") / "profile.json"
    assert_clean_failure(run_cli("profile", "list", "--profiles", not_a_folder),
                         f"{not_a_folder}: no such folder of profiles")


@pytest.mark.parametrize("case", ["json_seam_text", "zip_encrypted", "folder_fifo"])
def test_profile_show_of_a_bad_bundle_exits_2_in_one_line(pencil, tmp_path, monkeypatch, case):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    [bundle] = bad_bundles(pencil, tmp_path / "home" / "profiles", (case,))
    assert_clean_failure(run_cli("profile", "show", bundle), str(bundle))
    assert_clean_failure(run_cli("profile", "show", case), str(bundle))  # by name
    assert run_cli("profile", "show", "pencil").returncode == 0


def test_the_catalogue_skips_bad_bundles_once_and_offers_the_rest(pencil, tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    extra = tmp_path / "pens"
    fountain(pencil, extra)
    bad = bad_bundles(pencil, extra, tuple(CORPUS))  # FIFOs too: nothing may wait on them
    catalog = Catalog([extra])
    assert catalog.names == [*BUNDLED_PENS, "fountain"]
    assert len(catalog.skipped) == len(bad)
    for bundle in bad:
        assert sum(line.startswith(f"{bundle}: ") for line in catalog.skipped) == 1, bundle
    assert all("\n" not in line for line in catalog.skipped)


def test_the_catalogue_skips_a_loop_too_long_to_serve(pencil, tmp_path, monkeypatch):
    """A 100 Hz tactile pattern is served at the sound's 48 kHz: 45,000 frames become 21,600,000,
    over the limit of a served WAV."""
    import dataclasses

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    pattern = dataclasses.replace(pencil.meta.tactile, rate=100, subpattern_ms=30000.0)
    meta = pencil.meta.model_copy(update={"name": "slow", "tactile": pattern})
    slow = save_profile(PenProfile(meta, np.zeros(pattern.frames, np.float32), pencil.sound),
                        tmp_path / "pens" / "slow")
    assert load_profile(slow).meta.tactile.frames == 45000  # a bundle within every limit
    catalog = Catalog([tmp_path / "pens"])
    assert catalog.names == list(BUNDLED_PENS)
    assert catalog.skipped == [f"{slow}: its tactile pattern would be 21,600,000 frames served at "
                               f"48000 Hz; the limit is {MAX_WAV_FRAMES:,}"]


# --- fresh interpreters: bounded memory, and a real server -----------------------------------

def limited(command: list[str], home: Path) -> subprocess.CompletedProcess:
    """Run ``command`` with at most :data:`ADDRESS_LIMIT` bytes of address space."""
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_LIMIT, ADDRESS_LIMIT))

    env = {**os.environ, "REALPEN_HOME": str(home), "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run(command, preexec_fn=limit, env=env, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.slow
def test_zip_bombs_are_refused_within_bounded_memory(pencil, tmp_path):
    """A 2 GiB tactile.wav and a 1 GiB profile.json, each a bundle of about 2 MB, under a 2 GiB
    address-space limit: refused by name; the other pens are listed."""
    home = tmp_path / "home"
    profiles = home / "profiles"
    fountain(pencil, profiles)
    realpen = [sys.executable, "-m", "realpen"]
    # The same limit lets a good call through, so a failure below is the bombs' doing.
    before = limited([*realpen, "profile", "list"], home)
    assert before.returncode == 0 and before.stderr == "", before.stderr
    assert "fountain: fountain pen" in before.stdout

    source = save_profile(pencil, tmp_path / "work" / "pen")
    bombs = [wav_bomb(source, profiles / "wavbomb.zip", gib=2),
             whitespace_bomb(source, profiles / "spacebomb.zip", mib=1024)]
    assert all(bomb.stat().st_size < 3 * MiB for bomb in bombs)
    with zipfile.ZipFile(bombs[0]) as archive:
        assert archive.getinfo("tactile.wav").file_size == 2 * GiB + 44
    after = limited([*realpen, "profile", "list"], home)
    assert after.returncode == 0, after.stderr
    assert after.stdout == before.stdout
    warnings = after.stderr.splitlines()
    assert warnings == sorted(warnings) and len(warnings) == 2, after.stderr
    assert warnings[0].startswith(f"{WARNING}{bombs[1]}: profile.json is declared 1,073,")
    assert warnings[1].startswith(f"{WARNING}{bombs[0]}: tactile.wav is declared "
                                  f"{2 * GiB + 44:,} bytes")
    shown = limited([*realpen, "profile", "show", "wavbomb"], home)
    assert_clean_failure(shown, f"{bombs[0]}: tactile.wav is declared")


@pytest.mark.slow
def test_serve_with_bad_bundles_starts_warns_once_and_offers_the_others(pencil, tmp_path):
    import httpx

    extra = tmp_path / "pens"
    fountain(pencil, extra)
    bad = bad_bundles(pencil, extra, ("zip_encrypted", "zip_unknown_method", "json_deep",
                                      "json_long_number", "json_seam_text", "folder_symlink"))
    bad += bad_bundles(pencil, tmp_path / "home" / "profiles", ("zip_declared_too_big",))
    with serve(tmp_path, "--profiles", str(extra), stderr_to=tmp_path / "stderr.txt") as server:
        profiles = httpx.get(server.base + "api/profiles").json()["profiles"]
        assert [p["name"] for p in profiles] == [*BUNDLED_PENS, "fountain"]
        wav = httpx.get(server.base + "api/profiles/fountain/tactile.wav")
        assert wav.status_code == 200
        assert len(sf.read(io.BytesIO(wav.content))[0]) == pencil.meta.tactile.frames
        output = server.stop()
        errors = server.errors()
    assert "Traceback" not in output + errors
    for bundle in bad:
        lines = [line for line in output.splitlines() if str(bundle) in line]
        assert len(lines) == 1 and lines[0].startswith(f"  skipped profile: {bundle}: "), \
            (bundle, output)
    assert errors == "", errors


def test_profile_json_limit_is_checked_before_the_bytes_are_read(good, tmp_path, monkeypatch):
    """A folder's files are sized by stat before they are opened: a 1 GiB (sparse)
    profile.json is refused without opening anything."""
    sparse(good / "profile.json", GiB)
    real_open = os.open
    opened = []
    monkeypatch.setattr(os, "open", lambda path, *args, **kw: opened.append(path)
                        or real_open(path, *args, **kw))
    with pytest.raises(RealPenError, match="profile.json is 1,073,741,824 bytes"):
        load_profile(good)
    assert opened == []


def test_reads_are_bounded_even_when_a_size_lies(good, tmp_path, monkeypatch):
    """The sizes checked first (stat, a zip entry's header) can be out of date or wrong; the
    read that follows takes at most limit + 1 bytes and refuses more."""
    sparse(good / "tactile.wav", 3 * GiB)
    real_lstat = os.lstat

    def understated(path, *args, **kwargs):  # the file grows after it was sized
        info = real_lstat(path, *args, **kwargs)
        if str(path).endswith("tactile.wav"):
            return os.stat_result((info.st_mode, *info[1:6], 1000, *info[7:]))
        return info

    monkeypatch.setattr(os, "lstat", understated)
    with pytest.raises(RealPenError, match=f"tactile.wav grew, while it was read, to more than "
                                           f"its limit of {MAX_WAV_BYTES:,} bytes"):
        load_profile(good)
    monkeypatch.undo()

    # A zip reader that inflated past the declared size would be stopped the same way.
    bundle = zip_of(save_profile(resolve_profile("pencil"), tmp_path / "z"), tmp_path / "z.zip")
    asked = []

    def endless(self, entry, *args, **kwargs):
        class Stream(io.BytesIO):
            def read(self, size=-1):
                asked.append(size)
                return bytes(size)
        return Stream()

    monkeypatch.setattr(zipfile.ZipFile, "open", endless)
    with pytest.raises(RealPenError, match=f"profile.json inflates to more than its limit of "
                                           f"{MAX_JSON_BYTES:,} bytes"):
        load_profile(bundle)
    assert asked == [MAX_JSON_BYTES + 1]


# --- found in review: slow, huge or unwritable documents -------------------------------------

def test_an_unterminated_string_of_escaped_quotes_is_refused_at_once(good):
    import time

    write_document(good, '{"tool": "' + '\\"' * 1_500_000)
    start = time.perf_counter()
    with pytest.raises(RealPenError, match="not valid JSON"):
        load_profile(good)
    assert time.perf_counter() - start < 10  # was quadratic: hours at this size


def test_a_document_of_too_many_values_is_refused_before_validation(good):
    document = read_document(good)
    document["tactile"]["subpatterns"] = [[0] * 600_000]
    write_document(good, document)
    with pytest.raises(RealPenError, match="holds more than 524,288 values"):
        load_profile(good)


def test_a_lone_surrogate_is_refused_and_the_catalogue_skips_it(good, tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    document = read_document(good)
    write_document(good, json.dumps(document).replace('"tool": "', '"tool": "\\ud800', 1))
    with pytest.raises(RealPenError, match="not valid Unicode"):
        load_profile(good)
    catalog = Catalog([good.parent])
    assert catalog.names == list(BUNDLED_PENS) and len(catalog.skipped) == 1
    assert len(json.dumps(catalog.to_json())) > 0  # the others are served


def test_numbers_that_load_but_overflow_later_are_refused_or_ignored(good, tmp_path):
    document = read_document(good)
    document["tactile"]["subpatterns"][0][0]["frequency_hz"] = 1e308
    write_document(good, document)
    with pytest.raises(RealPenError, match="frequency_hz"):
        load_profile(good)
    document["tactile"]["subpatterns"][0][0]["frequency_hz"] = 175.0
    document["provenance"]["tactile_parameters"]["selection_unit_ms"] = 1e-308
    write_document(good, document)
    result = run_cli("export", str(good), "-f", "wav", "-o", str(tmp_path / "p.wav"))
    assert result.returncode == 0, result.stderr  # the odd provenance is not needed to export
