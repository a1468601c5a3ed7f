"""The protocol detector names what a few kB of bytes decode as, and nothing for garbage; ``hil decode auto``."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from drivers.detect import MIN_RUN, detect
from hil.cli import main
from test_drivers_framing import CODECS

KINDS = {"kvh1750": "imu", "xsens-mtdata2": "imu", "tts1": "table"}


def stream(protocol: str, frames: int, first: int = 0) -> bytes:
    make_codec, make_frame = CODECS[protocol]
    codec = make_codec()
    return b"".join(make_frame(codec, i) for i in range(first, first + frames))


def garbage(n: int, seed: int = 7) -> bytes:
    return np.random.default_rng(seed).integers(0, 256, n, dtype=np.uint8).tobytes()


@pytest.mark.parametrize("protocol", sorted(CODECS))
def test_each_shipped_protocol_is_named_from_its_frames(protocol):
    found = detect(stream(protocol, 120)[7:])  # starting inside a frame, as a port's tail does
    assert (found.protocol, found.kind) == (protocol, KINDS[protocol])
    assert found.frames == 119


@pytest.mark.parametrize("protocol", sorted(CODECS))
def test_frames_among_garbage_are_found(protocol):
    data = garbage(3000, 1) + stream(protocol, 40) + garbage(500, 2) + stream(protocol, 40, 40)
    assert detect(data).protocol == protocol


@pytest.mark.parametrize("seed", range(5))
def test_random_bytes_decode_as_nothing(seed):
    assert detect(garbage(1 << 16, seed)) is None


@pytest.mark.parametrize("protocol", sorted(CODECS))
def test_frames_too_few_in_a_row_do_not_count(protocol):
    frames = [stream(protocol, 1, i) for i in range(4)]
    lone = b"".join(garbage(100, i) + f for i, f in enumerate(frames))  # valid, never MIN_RUN in a row
    assert detect(lone) is None
    assert detect(b"".join(frames[:MIN_RUN])).protocol == protocol


def test_the_protocol_with_the_most_frames_wins():
    data = stream("tts1", 30) + garbage(200) + stream("kvh1750", 60)
    assert detect(data).protocol == "kvh1750"


@pytest.mark.parametrize("protocol", sorted(CODECS))
def test_decode_auto_names_and_decodes_each_capture(tmp_path, capsys, protocol):
    capture = tmp_path / "capture.bin"
    capture.write_bytes(garbage(300) + stream(protocol, 500))
    assert main(["decode", "auto", str(capture), "--out", str(tmp_path / "out.csv")]) == 0
    counters = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert counters["protocol"] == protocol and counters["frames"] == 500 and counters["skipped_bytes"] >= 300
    rows = list(csv.reader(open(tmp_path / "out.csv")))
    assert len(rows) == 501


@pytest.mark.parametrize("content", ["garbage", "xsens-mtdata2"])
def test_decoding_a_file_without_a_frame_of_the_protocol_is_one_line_and_exit_2(tmp_path, capsys, content):
    """Random bytes, or another protocol's capture, decoded as kvh1750: bad input, and no empty CSV left."""
    capture = tmp_path / "capture.bin"
    capture.write_bytes(garbage(5000) if content == "garbage" else stream(content, 200))
    assert main(["decode", "kvh1750", str(capture), "--out", str(tmp_path / "out.csv")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert f"{capture}: no valid kvh1750 frame found" in captured.err
    assert not (tmp_path / "out.csv").exists()
