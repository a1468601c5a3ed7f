"""Feed every codec's framer a device stream damaged in transit; print what it lost, frames/s, failures.

Usage: python benchmarks/fuzz_codecs.py [--frames N] [--seed S] [--codec NAME ...]

Byte codecs (kvh1750, tts1, xsens-mtdata2, stim300): the device sends frames with consecutive counters (they
wrap during the run); each frame reaches the framer intact or, with probability 1/2, damaged by one of:
bit flips, truncation, a random body behind a valid header, garbage before a frame cut at its end,
garbage instead of the frame, overwritten bytes, duplicated bytes. The stream is fed in random reads
of 1..4096 bytes, 20 000 frames per framer instance, without host times (the counters alone carry the
sequence). Reported per codec:

* intact, lost_intact: frames sent intact, and those of them the framer did not deliver.
* explained: lost intact frames that a protocol limit accounts for (printed with the figures); the rest
  is ``beyond``, the framer's own resynchronisation loss, with a target of at most 1e-4 of intact.
* false_accepts: delivered frames whose values were never sent, each one found by the benchmark as
  damaged bytes that pass the frame check (else it is a failure); recovered: damaged frames whose bytes
  still decode to the frame that was sent; index_slips: times the index of the intact frames delivered
  moved off the frames' true distance (after an accepted frame with a wrong counter).
* failures: an exception escaping a framer or parser, bytes not accounted for (every byte fed must end
  in a decoded frame, the skipped count, or the buffer), a delivered value found nowhere in the stream,
  a frame delivered twice, or a codec that does not decode what it encoded.

CAN (can-dbc) and ACL lines are fuzzed message by message and report decoded, corrupt and failures.
"""

from __future__ import annotations

import argparse
import bisect
import math
import random
import time
from collections.abc import Callable
from dataclasses import fields, is_dataclass

import numpy as np

from drivers.acl import TREE, AclCommand, AclError, format_message, parse_message
from drivers.can_dbc import CanDbcCodec
from drivers.codec import RawChunk
from drivers.framing import ByteCodec, SequenceUnwrapper
from drivers.kvh1750 import Kvh1750Codec
from drivers.stim300 import Stim300Codec
from drivers.tts1 import Tts1Codec
from drivers.xsens import XsensCodec
from drivers.can_settings import CanSignals
from hil.samples import ImuSample, TableSample

BLOCK = 20_000  # frames per framer instance
TARGET = 1e-4  # lost intact frames beyond the protocol limits, per intact frame
WINDOW = SequenceUnwrapper.REORDER_WINDOW + 1  # frames after a wrong counter that the sequence rules may drop

LIMITS = {
    "cut": "a frame cut short whose missing tail equals the next frame's first bytes is a valid frame: "
           "it is delivered and the next frame, its sync taken, is lost",
    "check": "damage the frame check cannot see (8-bit sum of xsens-mtdata2 behind its structure and "
             "unit-DeltaQ checks, 2^-16 for the CRC-16 of tts1, 2^-32 for the CRC-32 of kvh1750 and stim300): the "
             "damaged frame is accepted and swallows the intact bytes it overlaps",
    "false_sync": "a sync word inside garbage or a damaged frame, whose bytes from there pass the check: "
                  "the protocol cannot tell it from a frame, and the intact bytes it overlaps are lost",
    "counter": f"an accepted damaged frame with a wrong (or no) counter: the sequence rules drop up to "
               f"{WINDOW} frames after it as repeats or late",
    "unconfirmed": "after such a frame a 16-bit or wider counter seems to jump far: every frame is the "
                   "unconfirmed jump (counted corrupt) until two consecutive frames arrive intact",
}


def _imu_sample(rng: random.Random, i: int) -> ImuSample:
    return ImuSample(i, tuple(rng.uniform(-1e-3, 1e-3) for _ in range(3)),
                     tuple(rng.uniform(-0.2, 0.2) for _ in range(3)), device_time=i / 400, status=0x77)


DAMAGE = ("bit flips", "truncation", "random body", "garbage + cut frame", "garbage only", "overwritten",
          "duplicated bytes")


def _mutate(rng: random.Random, frame: bytes) -> tuple[bytes, int, int]:
    """One random kind of damage: (damaged bytes, offset of the frame's start in them, kind)."""
    kind = rng.randrange(len(DAMAGE))
    if kind == 0:  # bit flips
        b = bytearray(frame)
        for _ in range(rng.randint(1, 3)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        return bytes(b), 0, kind
    if kind == 1:  # truncation
        return frame[: rng.randrange(len(frame))], 0, kind
    if kind == 2:  # random frame body behind a valid header
        return frame[:4] + rng.randbytes(len(frame) - 4), 0, kind
    if kind == 3:  # garbage, then the frame damaged at its end
        garbage = rng.randbytes(rng.randint(1, 40))
        return garbage + frame[:-1] + bytes([frame[-1] ^ 0xFF]), len(garbage), kind
    if kind == 4:  # pure random bytes instead of the frame
        return rng.randbytes(rng.randint(1, 2 * len(frame))), -1, kind
    if kind == 5:  # overwritten bytes
        return frame[: len(frame) // 2] + rng.randbytes(3) + frame[len(frame) // 2 + 3:], 0, kind
    k = rng.randrange(1, len(frame))  # duplicated bytes: a stutter of up to 4 bytes
    return frame[:k] + frame[k - rng.randint(1, min(4, k)):k] + frame[k:], 0, kind


def _same(a, b) -> bool:
    """Equal records, floats up to the float32 precision of the wire."""
    if is_dataclass(a):
        return type(a) is type(b) and all(_same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-12)
    return a == b


def _counter(codec: ByteCodec, frame: bytes) -> int | None:
    """The counter of one valid frame as the codec reads it (None for a protocol without)."""
    _, rows = codec.parse(np.frombuffer(frame, np.uint8), np.zeros(1, dtype=np.int64), np.array([len(frame)]))
    counters = codec.sequences(rows)
    return None if counters is None else int(counters[0])


def _valid_windows(codec: ByteCodec, stream: bytearray, starts: list[int], ends: list[int],
                   damaged: list[int]) -> list[tuple[int, int, object, int, int | None]]:
    """Every (offset, length, record, slot, counter) where a sync word starts in the damaged bytes of a slot and
    the bytes from there form a frame the codec accepts: what the protocol cannot tell from a frame."""
    sync, header_size, out = codec.sync, codec.header_size, []
    buf = np.frombuffer(bytes(stream), np.uint8)
    for k in damaged:
        stop = ends[k] + len(sync) - 1
        p = stream.find(sync, starts[k], stop)
        while p >= 0:
            if len(stream) - p >= header_size:
                length = int(codec.frame_lengths(buf, np.array([p]))[0])
                if 0 < length <= len(stream) - p:
                    try:
                        frame = bytes(stream[p:p + length])
                        out.append((p, length, codec.decode(frame), k, _counter(codec, frame)))
                    except ValueError:
                        pass
            p = stream.find(sync, p + 1, stop)
    return out


def fuzz_bytes(codec: ByteCodec, make_record: Callable[[random.Random, int], object], n: int,
               rng: random.Random, verbose: bool = False) -> dict:
    stats = dict(frames=0, intact=0, delivered=0, corrupt=0, lost_intact=0, **{k: 0 for k in LIMITS},
                 beyond=0, false_accepts=0, recovered=0, index_slips=0, failures=0)
    first = (1 << 32) - n // 2  # the 32-bit tts1 counter wraps half way, the narrower ones many times
    elapsed = 0.0

    def fail(message: str) -> None:
        stats["failures"] += 1
        print(f"  FAILURE {codec.name}: {message}")

    for block_start in range(0, n, BLOCK):
        count = min(BLOCK, n - block_start)
        stream = bytearray()
        starts, ends, at, kinds, intact, records, damaged, counters = [], [], [], [], [], [], [], []
        for k in range(count):
            source = make_record(rng, first + block_start + k)
            frame = codec.encode(source)
            record = codec.decode(frame)
            if not _same(record, source):
                fail(f"{source} decodes as {record}")
            piece, offset, kind = _mutate(rng, frame) if rng.random() < 0.5 else (frame, 0, -1)
            starts.append(len(stream))
            stream += piece
            ends.append(len(stream))
            at.append(offset)
            kinds.append(kind)
            records.append(record)
            counters.append(_counter(codec, frame))
            intact.append(piece == frame)  # also a mutation that undid itself (a bit flipped twice)
            if piece != frame:
                damaged.append(k)
        stats["frames"] += count
        stats["intact"] += count - len(damaged)
        framer = codec.framer()
        batches, pos = [], 0
        t0 = time.perf_counter()
        try:
            while pos < len(stream):
                step = rng.randint(1, 4096)
                batches.append(framer.feed_bytes(bytes(stream[pos:pos + step]), math.nan))
                pos += step
        except Exception as exc:  # the point of the fuzz: report anything that escapes
            elapsed += time.perf_counter() - t0
            fail(f"{type(exc).__name__}: {exc}")
            continue
        elapsed += time.perf_counter() - t0
        decoded = [(codec.record(row), int(index), int(size)) for b in batches
                   for row, index, size in zip(b.rows, b.sync_index, b.size)]
        if sum(size for _, _, size in decoded) + framer.counters.skipped_bytes + framer.buffered != len(stream):
            fail("bytes not accounted for")
        stats["delivered"] += len(decoded)
        stats["corrupt"] += framer.counters.corrupt

        # What the protocol cannot tell from a frame, and the intact frames each such window may cost.
        windows = _valid_windows(codec, stream, starts, ends, damaged)
        window_records = {w[2] for w in windows}
        cause: dict[int, str] = {}
        for p, length, record, k, counter in windows:
            limit = "cut" if record == records[k] else "check" if p == starts[k] + at[k] else "false_sync"
            j = bisect.bisect_right(starts, p) - 1
            while j < count and starts[j] < p + length:
                if j != k and intact[j] and ends[j] > p:
                    cause.setdefault(j, limit)
                j += 1
            if counter != counters[k]:
                for j in range(k + 1, min(k + 1 + WINDOW, count)):
                    if intact[j]:
                        cause.setdefault(j, "counter")
                # A far jump is confirmed only by the frame right after it: until two consecutive
                # frames arrive intact, each one is the unconfirmed jump.
                j = k + 1
                while j < count and not (intact[j] and j + 1 < count and intact[j + 1]):
                    if intact[j]:
                        cause.setdefault(j, "unconfirmed")
                    j += 1
                if j < count:
                    cause.setdefault(j, "unconfirmed")

        slot_of = {r: k for k, r in enumerate(records)}
        got = [False] * count
        reference, offset = None, 0  # (slot, index) of the first intact frame delivered; index error
        for record, index, _ in decoded:
            k = slot_of.get(record)
            if k is None:
                if record in window_records:
                    stats["false_accepts"] += 1
                else:
                    fail(f"delivered {record}, found nowhere in the stream")
                continue
            if got[k]:
                fail(f"frame {k} of block {block_start // BLOCK} delivered twice")
                continue
            got[k] = True
            if not intact[k]:
                stats["recovered"] += 1
            elif reference is None:
                reference = (k, index)
            elif index - reference[1] - (k - reference[0]) * codec.sequence_step != offset:
                offset = index - reference[1] - (k - reference[0]) * codec.sequence_step
                stats["index_slips"] += 1
        for k in range(count):
            if intact[k] and not got[k]:
                stats["lost_intact"] += 1
                limit = cause.get(k)
                stats[limit or "beyond"] += 1
                if limit is None and verbose:
                    around = " ".join(f"{j - k:+d}:{'ok' if intact[j] else DAMAGE[kinds[j]]}"
                                      f"{'' if got[j] else '(lost)'}" for j in range(max(k - 3, 0), min(k + 3, count)))
                    near = " ".join(f"{w[3] - k:+d}@{w[0] - starts[w[3]]}:seq {w[4]} for {counters[w[3]]}"
                                    for w in windows if abs(w[3] - k) <= 12)
                    print(f"  {codec.name}: block {block_start // BLOCK} frame {k} lost beyond the limits; {around}; "
                          f"valid windows near: {near or 'none'}")
    stats["seconds"] = elapsed
    return stats


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
                batch = framer.feed_chunk(chunk)
                stats["decoded"] += len(batch)
                decoded_bytes += int(batch.size.sum())
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


def _acl_units(node=TREE, path: str = "") -> list[tuple[str, tuple[str, ...], bool]]:
    """Every command and query of the ACL tree: (path, argument kinds, is a query)."""
    found = []
    for child in node.children:
        full = f"{path}:{child.name}" if path else child.name
        found += [(full, kinds, query) for kinds, query in ((child.args, False), (child.query, True))
                  if kinds is not None]
        found += _acl_units(child, full)
    return found


def fuzz_acl(n: int, rng: random.Random) -> dict:
    units = _acl_units()
    words = {"axis": ["1", "2", "3"], "axis|ALL": ["1", "2", "3", "ALL"], "word": ["Float", "Enable", "+"],
             "mode": ["Position", "Rate", "Synthesis", "Off"], "int": [1.0, 2.0, 360.0]}
    stats = dict(frames=0, decoded=0, corrupt=0, failures=0)
    t0 = time.perf_counter()
    for _ in range(n):
        path, kinds, query = rng.choice(units)
        args = tuple(rng.choice(words[k]) if k in words else rng.uniform(-1e3, 1e3) for k in kinds)
        if query:
            args = tuple("1" if a == "ALL" else a for a in args)
        command = AclCommand(path, args, query)
        line = format_message(command)
        if rng.random() < 0.5:
            b = bytearray(line)
            for _ in range(rng.randint(1, 3)):
                b[rng.randrange(len(b))] = rng.randrange(256)
            line = bytes(b)
        stats["frames"] += 1
        try:
            parsed = parse_message(line)
            stats["decoded"] += 1
            if line == format_message(command) and (len(parsed) != 1 or not _close(parsed[0], command)):
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
    return a.header == b.header and len(a.args) == len(b.args) and all(
        x == y or (isinstance(x, float) and math.isclose(x, y, rel_tol=1e-9)) for x, y in zip(a.args, b.args))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1_000_000, help="frames per codec (default 1 000 000)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--codec", nargs="*", default=["kvh1750", "tts1", "xsens-mtdata2", "stim300", "can-dbc", "acl"])
    parser.add_argument("--verbose", action="store_true", help="print each intact frame lost beyond the limits")
    args = parser.parse_args()
    kvh, tts1, xsens = Kvh1750Codec(rate_hz=1000), Tts1Codec(), XsensCodec(rate_hz=400)
    stim = Stim300Codec(rate_hz=1000, datagram=0xA5)  # the temperatures too: every field of the longer datagram
    runs = {
        "kvh1750": lambda r: fuzz_bytes(kvh, lambda r, i: kvh.from_sample(_imu_sample(r, i)), args.frames, r,
                                        args.verbose),
        "tts1": lambda r: fuzz_bytes(tts1, lambda r, i: tts1.from_sample(TableSample(
            i, tuple(r.uniform(-3.1, 3.1) for _ in range(3)), latch_delay=5e-5, status=0x21)), args.frames, r,
            args.verbose),
        "xsens-mtdata2": lambda r: fuzz_bytes(xsens, lambda r, i: xsens.from_sample(_imu_sample(r, i)),
                                              args.frames, r, args.verbose),
        "stim300": lambda r: fuzz_bytes(stim, lambda r, i: stim.from_sample(_imu_sample(r, i)), args.frames, r,
                                        args.verbose),
        "can-dbc": lambda r: fuzz_can(args.frames, r),
        "acl": lambda r: fuzz_acl(args.frames, r),
    }
    if any(name in ("kvh1750", "tts1", "xsens-mtdata2", "stim300") for name in args.codec):
        print(f"protocol limits (lost intact frames they explain; target: the rest <= {TARGET:g} of intact):")
        for name, text in LIMITS.items():
            print(f"  {name}: {text}")
    total_failures, missed = 0, []
    for name in args.codec:
        stats = runs[name](random.Random(f"{args.seed}/{name}"))  # a codec's figures do not depend on the others
        total_failures += stats["failures"]
        rate = stats["frames"] / stats["seconds"] if stats["seconds"] else float("inf")
        if "intact" in stats:
            intact = max(stats["intact"], 1)
            explained = " ".join(f"{k}={stats[k]}" for k in LIMITS)
            share = stats["beyond"] / intact
            met = share <= TARGET
            if not met:
                missed.append(name)
            print(f"{name:14s} frames={stats['frames']} intact={stats['intact']} delivered={stats['delivered']} "
                  f"corrupt={stats['corrupt']} lost_intact={stats['lost_intact']} "
                  f"({stats['lost_intact'] / intact:.1e} of intact) explained: {explained} "
                  f"beyond={stats['beyond']} ({share:.1e}, target {'met' if met else 'MISSED'}) "
                  f"false_accepts={stats['false_accepts']} recovered={stats['recovered']} "
                  f"index_slips={stats['index_slips']} failures={stats['failures']} {rate:,.0f} frames/s")
        else:
            print(f"{name:14s} frames={stats['frames']} decoded={stats['decoded']} corrupt={stats['corrupt']} "
                  f"failures={stats['failures']} {rate:,.0f} frames/s")
    print(f"failures: {total_failures}" + (f"; loss target missed: {' '.join(missed)}" if missed else ""))
    raise SystemExit(1 if total_failures else 0)


if __name__ == "__main__":
    main()
