"""Push random and mutated frames through every codec's framer; print frames/s and any failure.

Usage: python benchmarks/fuzz_codecs.py [--frames N] [--seed S] [--codec NAME ...]

A failure is an exception escaping a framer or parser, or bytes not accounted for (every byte fed
must end in a decoded frame, the skipped count, or the buffer). Also reported: intact frames not
recovered and damaged frames accepted as valid. Both happen only when the damaged bytes form a valid
frame: a frame cut short by its last byte, followed by a frame that starts with that very byte
(about 1e-5 of frames), or damage that an 8-bit checksum (Xsens) cannot see.
"""

from __future__ import annotations

import argparse
import math
import random
import time
from collections.abc import Callable

from drivers.acl import COMMANDS, AclCodec, AclCommand, AclError
from drivers.can_dbc import CanDbcCodec
from drivers.codec import RawChunk
from drivers.kvh1750 import Kvh1750Codec
from drivers.tts1 import Tts1Codec
from drivers.xsens import XsensCodec
from hil.config import CanSignals
from hil.samples import ImuSample, TableSample

BLOCK = 20_000  # frames per framer instance


def _imu_sample(rng: random.Random, i: int) -> ImuSample:
    return ImuSample(i, tuple(rng.uniform(-1e-3, 1e-3) for _ in range(3)),
                     tuple(rng.uniform(-0.2, 0.2) for _ in range(3)), device_time=i / 400, status=0x77)


def _mutate(rng: random.Random, frame: bytes) -> bytes:
    """One random kind of damage."""
    kind = rng.randrange(6)
    if kind == 0:  # bit flips
        b = bytearray(frame)
        for _ in range(rng.randint(1, 3)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        return bytes(b)
    if kind == 1:  # truncation
        return frame[: rng.randrange(len(frame))]
    if kind == 2:  # random frame body behind a valid header
        return frame[:4] + rng.randbytes(len(frame) - 4)
    if kind == 3:  # garbage, then the frame damaged at its end
        return rng.randbytes(rng.randint(1, 40)) + frame[:-1] + bytes([frame[-1] ^ 0xFF])
    if kind == 4:  # pure random bytes
        return rng.randbytes(rng.randint(1, 2 * len(frame)))
    return frame[: len(frame) // 2] + rng.randbytes(3) + frame[len(frame) // 2 + 3:]  # overwritten bytes


def fuzz_bytes(codec, make_frame: Callable[[random.Random, int], bytes], n: int, rng: random.Random) -> dict:
    stats = dict(frames=0, decoded=0, corrupt=0, lost_intact=0, false_accepts=0, failures=0)
    pool = [make_frame(rng, i) for i in range(512)]
    records = [codec.decode(f) for f in pool]
    elapsed = 0.0
    for block_start in range(0, n, BLOCK):
        stream, expected = bytearray(), []
        for _ in range(min(BLOCK, n - block_start)):
            j = rng.randrange(len(pool))
            frame = pool[j] if rng.random() < 0.5 else _mutate(rng, pool[j])
            stream += frame
            if frame == pool[j]:  # also a mutation that undid itself (a bit flipped twice)
                expected.append(records[j])
        stats["frames"] += min(BLOCK, n - block_start)
        framer = codec.framer()
        decoded, pos = [], 0
        t0 = time.perf_counter()
        try:
            while pos < len(stream):
                step = rng.randint(1, 4096)
                decoded += framer.feed(bytes(stream[pos:pos + step]), math.nan)
                pos += step
        except Exception as exc:  # the point of the fuzz: report anything that escapes
            stats["failures"] += 1
            print(f"  FAILURE {codec.name}: {type(exc).__name__}: {exc}")
            continue
        finally:
            elapsed += time.perf_counter() - t0
        if sum(d.size for d in decoded) + framer.counters.skipped_bytes + framer.buffered != len(stream):
            stats["failures"] += 1
            print(f"  FAILURE {codec.name}: bytes not accounted for")
        stats["decoded"] += len(decoded)
        stats["corrupt"] += framer.counters.corrupt
        lost, false = _match([d.record for d in decoded], expected)
        stats["lost_intact"] += lost
        stats["false_accepts"] += false
    stats["seconds"] = elapsed
    return stats


def _match(got: list, expected: list) -> tuple[int, int]:
    """(expected records missing from ``got``, records in ``got`` that were never sent intact)."""
    p = lost = false = 0
    for record in got:
        window = expected[p:p + 8]
        if record in window:
            k = window.index(record)
            lost += k
            p += k + 1
        else:
            false += 1
    return lost + len(expected) - p, false


def fuzz_can(n: int, rng: random.Random) -> dict:
    signals = CanSignals()
    codec = CanDbcCodec("configs/imu_lab_highres.dbc", 400.0, signals.gyro, signals.accel, signals.sync,
                        signals.status)
    stats = dict(frames=0, decoded=0, corrupt=0, failures=0)
    elapsed, i, fed, decoded_bytes = 0.0, 0, 0, 0
    framer = codec.framer()
    while stats["frames"] < n:
        messages = codec.encode(codec.from_sample(_imu_sample(rng, i)))
        i += 1
        chunks = []
        for m in messages:
            kind = rng.randrange(16)
            data, arbitration_id = bytes(m.data), m.arbitration_id
            if kind == 0:
                continue  # lost on the bus
            if kind == 1:
                data = data[: rng.randrange(8)]
            elif kind == 2:
                data = rng.randbytes(rng.randint(0, 8))
            elif kind == 3:
                arbitration_id = rng.randrange(0x800)
            chunks.append(RawChunk("imu", math.nan, data, arbitration_id, False))
        stats["frames"] += len(messages)
        t0 = time.perf_counter()
        try:
            for chunk in chunks:
                fed += len(chunk.data)
                for d in framer.feed_chunk(chunk):
                    stats["decoded"] += 1
                    decoded_bytes += d.size
        except Exception as exc:  # the point of the fuzz: report anything that escapes
            stats["failures"] += 1
            print(f"  FAILURE can-dbc: {type(exc).__name__}: {exc}")
        elapsed += time.perf_counter() - t0
    if decoded_bytes + framer.counters.skipped_bytes + framer.buffered != fed:
        stats["failures"] += 1
        print("  FAILURE can-dbc: bytes not accounted for")
    stats["corrupt"] = framer.counters.corrupt
    stats["seconds"] = elapsed
    return stats


def fuzz_acl(n: int, rng: random.Random) -> dict:
    codec = AclCodec()
    headers = list(COMMANDS)
    words = {"axis": ["1", "2", "3", "ALL"], "mode": ["Position", "Rate", "Synthesis", "Off"], "onoff": ["ON", "OFF"]}
    stats = dict(frames=0, decoded=0, corrupt=0, failures=0)
    t0 = time.perf_counter()
    for _ in range(n):
        header = rng.choice(headers)
        args = tuple(rng.choice(words[k]) if k in words else rng.uniform(-1e3, 1e3) for k in COMMANDS[header])
        command = AclCommand(header, args)
        line = codec.format_command(command)
        if rng.random() < 0.5:
            b = bytearray(line)
            for _ in range(rng.randint(1, 3)):
                b[rng.randrange(len(b))] = rng.randrange(256)
            line = bytes(b)
        stats["frames"] += 1
        try:
            parsed = codec.parse_command(line)
            stats["decoded"] += 1
            if line == codec.format_command(command) and parsed != command and not _close(parsed, command):
                stats["failures"] += 1
                print(f"  FAILURE acl: {line!r} parsed as {parsed}")
        except AclError:
            stats["corrupt"] += 1
        except Exception as exc:
            stats["failures"] += 1
            print(f"  FAILURE acl: {type(exc).__name__}: {exc} on {line!r}")
    stats["seconds"] = time.perf_counter() - t0
    return stats


def _close(a: AclCommand, b: AclCommand) -> bool:
    """Equal up to the 10 significant digits numbers are sent with."""
    return a.header == b.header and all(
        x == y or (isinstance(x, float) and math.isclose(x, y, rel_tol=1e-9)) for x, y in zip(a.args, b.args))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1_000_000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--codec", nargs="*", default=["kvh1750", "tts1", "xsens-mtdata2", "can-dbc", "acl"])
    args = parser.parse_args()
    rng = random.Random(args.seed)
    kvh, tts1, xsens = Kvh1750Codec(rate_hz=1000), Tts1Codec(), XsensCodec(rate_hz=400)
    runs = {
        "kvh1750": lambda: fuzz_bytes(kvh, lambda r, i: kvh.encode(kvh.from_sample(_imu_sample(r, i))),
                                      args.frames, rng),
        "tts1": lambda: fuzz_bytes(tts1, lambda r, i: tts1.encode(tts1.from_sample(TableSample(
            i, tuple(r.uniform(-3.1, 3.1) for _ in range(3)), latch_delay=5e-5, status=0x21))), args.frames, rng),
        "xsens-mtdata2": lambda: fuzz_bytes(xsens, lambda r, i: xsens.encode(xsens.from_sample(_imu_sample(r, i))),
                                            args.frames, rng),
        "can-dbc": lambda: fuzz_can(args.frames, rng),
        "acl": lambda: fuzz_acl(args.frames, rng),
    }
    total_failures = 0
    for name in args.codec:
        stats = runs[name]()
        total_failures += stats["failures"]
        rate = stats["frames"] / stats["seconds"] if stats["seconds"] else float("inf")
        extra = "".join(f" {k}={stats[k]}" for k in ("lost_intact", "false_accepts") if k in stats)
        print(f"{name:14s} frames={stats['frames']} {rate:,.0f} frames/s decoded={stats['decoded']} "
              f"corrupt={stats['corrupt']}{extra} failures={stats['failures']}")
    print(f"failures: {total_failures}")
    raise SystemExit(1 if total_failures else 0)


if __name__ == "__main__":
    main()
