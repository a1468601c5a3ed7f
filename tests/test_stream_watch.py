"""The stream watch: bytes arriving for output.stream_timeout_s without a frame give one line naming the port
and what the bytes decode as; a stream that decodes is never judged."""

from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import make_config
from drivers.codec import RawChunk, StreamEvent
from drivers.decoder import StreamDecoder
from drivers.detect import DETECT_BYTES
from drivers.registry import imu_codec, make_codec
from hil.config import ConfigError, OutputConfig, parse_config
from hil.pipeline.settings import PipelineSettings
from hil.pipeline.stream_watch import StreamWatch
from test_detect import garbage, stream

PORTS = {"imu": "/dev/ttyUSB0", "table": "/dev/ttyUSB1"}
READ_S = 0.05  # host time between chunks
T0 = 1000.0


def watch_of(cfg, ports: dict[str, str] = PORTS) -> StreamWatch:
    return StreamWatch.of(PipelineSettings.of(cfg), ports)


def run(cfg, name: str, data: bytes, per_read: int = 240, watch: StreamWatch | None = None):
    """Feed ``data`` as stream ``name`` in reads of ``per_read`` bytes through the stream's decoder; (verdict,
    host time since the first chunk when it came, bytes fed until then)."""
    codec = imu_codec(cfg.imu, cfg.imu_rate_hz) if name == "imu" else make_codec("tts1")
    decoder, watch = StreamDecoder(codec), watch or watch_of(cfg)
    for k, at in enumerate(range(0, len(data), per_read)):
        chunk = RawChunk(name, T0 + k * READ_S, data[at:at + per_read])
        decoder.feed(chunk)
        verdict = watch.fed(chunk, decoder.counters.frames)
        if verdict:
            return verdict, k * READ_S, at + len(chunk.data)
    return None, None, len(data)


def test_table_frames_on_the_imu_port_say_the_ports_are_swapped():
    verdict, after, _ = run(make_config(), "imu", stream("tts1", 2000))
    assert verdict == "the imu port (/dev/ttyUSB0) carries tts1 frames: are the IMU and table ports swapped?"
    assert after == pytest.approx(5.0)


def test_imu_frames_on_the_table_port_say_the_ports_are_swapped():
    verdict, _, _ = run(make_config(), "table", stream("kvh1750", 2000), per_read=360)
    assert verdict == ("the turntable data port (/dev/ttyUSB1) carries kvh1750 frames: "
                       "are the IMU and table ports swapped?")


def test_another_imu_protocol_names_it_and_imu_protocol():
    verdict, _, _ = run(make_config(), "imu", stream("xsens-mtdata2", 3000))
    assert verdict == "the bytes on /dev/ttyUSB0 decode as xsens-mtdata2, not kvh1750 (imu.protocol)"


@pytest.mark.parametrize("name, keys", [("imu", "imu.baudrate and imu.protocol"),
                                        ("table", "turntable.baudrate and turntable.data_port")])
def test_garbage_names_the_bytes_and_the_baud_rate(name, keys):
    verdict, _, fed = run(make_config(), name, garbage(500_000), per_read=4000)  # 80 kB/s: 921600 baud
    assert verdict == f"no frame in {fed} bytes on {PORTS[name]}: check {keys}"
    assert fed > DETECT_BYTES  # counted in full, though only the last DETECT_BYTES are kept


def test_the_timeout_is_the_configured_one():
    cfg = make_config().model_copy(update={"output": OutputConfig(stream_timeout_s=2)})
    _, after, _ = run(cfg, "imu", garbage(100_000))
    assert after == pytest.approx(2.0)


@pytest.mark.parametrize("timeout", [0, -1])
def test_stream_timeout_must_be_positive(timeout):
    with pytest.raises(ConfigError, match="output.stream_timeout_s"):
        parse_config({"trial": {}, "site": {"latitude_deg": 0}, "output": {"stream_timeout_s": timeout}})


def test_a_stream_that_decodes_is_never_judged_and_a_frame_restarts_the_clock():
    cfg = make_config()
    frames = stream("kvh1750", 50)
    data = b"".join(garbage(4 * 240 * 20, k) + frames for k in range(10))  # 4 s of garbage between frames
    assert run(cfg, "imu", data)[0] is None
    watch = watch_of(cfg)
    assert run(cfg, "imu", frames + garbage(6 * 240 * 20), watch=watch)[0].startswith("no frame in")


def test_undecoded_bytes_kept_are_bounded():
    watch = StreamWatch(1e9, watch_of(make_config()).expected, PORTS)
    run(make_config(), "imu", garbage(1_000_000), per_read=4096, watch=watch)
    assert len(watch._streams["imu"].tail) == DETECT_BYTES


def test_an_outage_restarts_the_clock():
    watch = watch_of(make_config())
    chunk = RawChunk("imu", T0, garbage(100))
    assert watch.fed(chunk, 0) is None
    watch.event(StreamEvent("imu", T0 + 4.0, "outage"))
    assert watch.fed(RawChunk("imu", T0 + 6.0, garbage(100)), 0) is None
    assert watch.fed(RawChunk("imu", T0 + 11.0, garbage(100)), 0).startswith("no frame in 300 bytes")


def test_can_messages_that_never_make_a_frame_name_the_dbc_keys():
    cfg = make_config()
    cfg = cfg.model_copy(update={"imu": cfg.imu.model_copy(update={"protocol": "can-dbc"})})
    watch = watch_of(cfg, {"imu": "can://udp_multicast/239.74.163.2", "table": PORTS["table"]})
    verdicts = [watch.fed(RawChunk("imu", T0 + k * 0.01, bytes(8), arbitration_id=0x123), 0) for k in range(501)]
    assert not any(verdicts[:-1])
    assert verdicts[-1] == ("no frame in 501 CAN messages on can://udp_multicast/239.74.163.2: "
                            "check imu.can.dbc and imu.can.signals")


def test_the_verdict_depends_on_the_chunks_alone():
    data = stream("xsens-mtdata2", 3000)
    rng = np.random.default_rng(3)
    cuts = np.sort(rng.choice(len(data), 400, replace=False))
    pieces = np.split(np.frombuffer(data, np.uint8), cuts)
    verdicts = []
    for _ in range(2):
        watch = watch_of(make_config())
        verdicts.append(next((k, v) for k, piece in enumerate(pieces)
                             if (v := watch.fed(RawChunk("imu", T0 + 0.02 * k, piece.tobytes()), 0))))
    assert verdicts[0] == verdicts[1] and "xsens-mtdata2" in verdicts[0][1]
