"""Faults injected into one emulated device's stream of encoded frames, reproducibly from the trial seed.

Per frame, in this order: a drop burst may start (the frame and the next ``drop_burst - 1`` are not
sent); bits may flip (each byte with probability ``corrupt_byte_rate``); the frame may be cut short,
sent twice, or held back and sent after the next one. Frame damage depends on the medium: a byte
stream flips and cuts bytes; on CAN a message hit by a bit error is lost (the controllers' CRC
discards it) and a cut message has a short data field. Extra write latency (``jitter_ms``) and the
unplug window are applied by the device writer, which asks :meth:`FaultInjector.delay` and
:meth:`FaultInjector.unplugged`; a power cycle's silence is the device clock's
(:meth:`emulators.clocks.DeviceClock.powered`), which the writer counts as ``power_cycled``.
"""

from __future__ import annotations

from collections import Counter
from typing import Any, Protocol

import can
import numpy as np

from hil.config import FaultConfig
from hil.config_emulated import ImuFaultConfig

KINDS = ("dropped", "corrupted", "truncated", "duplicated", "reordered", "delayed", "unplugged", "unplugs",
         "power_cycled", "invalid")  # invalid: frames written whose sample the device flagged (flagged_samples)


def flagged_samples(faults: ImuFaultConfig, t: np.ndarray, since_on: np.ndarray,
                    rng: np.random.Generator) -> np.ndarray:
    """Per sample latched at trial time ``t`` (N,), ``since_on`` s after the IMU was powered on, whether the IMU
    flags it invalid: while it starts (``start_up_s``), inside the ``invalid_at_s`` window, or at random with
    ``invalid_rate`` (drawn from ``rng`` only then)."""
    flagged = since_on < faults.start_up_s
    if faults.invalid_at_s is not None:
        flagged |= (t >= faults.invalid_at_s) & (t < faults.invalid_at_s + faults.invalid_s)
    if faults.invalid_rate:
        flagged |= rng.random(len(t)) < faults.invalid_rate
    return flagged


class Damage(Protocol):
    """How bit errors and truncation look on one medium."""

    def corrupt(self, frame: Any, rate: float, rng: np.random.Generator) -> Any | None:
        """The frame with bit errors, or None when none hit it."""

    def truncate(self, frame: Any, rng: np.random.Generator) -> Any:
        """The frame cut short."""


class ByteDamage:
    """A serial line: flipped bits stay in the stream; a cut frame ends after 1..n-1 bytes."""

    def corrupt(self, frame: bytes, rate: float, rng: np.random.Generator) -> bytes | None:
        hit = np.flatnonzero(rng.random(len(frame)) < rate)
        if not len(hit):
            return None
        damaged = bytearray(frame)
        for i, bit in zip(hit, rng.integers(0, 8, len(hit))):
            damaged[i] ^= 1 << int(bit)
        return bytes(damaged)

    def truncate(self, frame: bytes, rng: np.random.Generator) -> bytes:
        return frame[:int(rng.integers(1, len(frame)))]


class CanDamage:
    """A CAN bus: a message with a bit error never arrives; a cut message keeps 0..dlc-1 data bytes."""

    def corrupt(self, frame: list[can.Message], rate: float, rng: np.random.Generator) -> list[can.Message] | None:
        hit = [rng.random(len(m.data)).min(initial=1.0) < rate for m in frame]
        return [m for m, h in zip(frame, hit) if not h] if any(hit) else None

    def truncate(self, frame: list[can.Message], rng: np.random.Generator) -> list[can.Message]:
        k = int(rng.integers(len(frame)))
        m = frame[k]
        cut = can.Message(arbitration_id=m.arbitration_id, is_extended_id=m.is_extended_id,
                          data=bytes(m.data[:int(rng.integers(len(m.data)))]))
        return frame[:k] + [cut] + frame[k + 1:]


class FaultInjector:
    """Applies one device's :class:`hil.config.FaultConfig`; :attr:`counts` holds what it injected per kind."""

    def __init__(self, faults: FaultConfig, damage: Damage, seed: int, device: int) -> None:
        self.faults, self.damage = faults, damage
        self.rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, device])))
        self.counts: Counter[str] = Counter({kind: 0 for kind in KINDS})
        self._drop_left = 0
        self._held: Any | None = None

    def frames(self, frame: Any) -> list[Any]:
        """What goes on the wire for this frame, in order (none, one or more frames)."""
        f, rng, counts = self.faults, self.rng, self.counts
        if self._drop_left == 0 and f.drop_rate and rng.random() < f.drop_rate:
            self._drop_left = f.drop_burst
        if self._drop_left:
            self._drop_left -= 1
            counts["dropped"] += 1
            return self._release([])
        if f.corrupt_byte_rate:
            damaged = self.damage.corrupt(frame, f.corrupt_byte_rate, rng)
            if damaged is not None:
                frame = damaged
                counts["corrupted"] += 1
        if f.truncate_rate and rng.random() < f.truncate_rate:
            frame = self.damage.truncate(frame, rng)
            counts["truncated"] += 1
        out = [frame]
        if f.duplicate_rate and rng.random() < f.duplicate_rate:
            out.append(frame)
            counts["duplicated"] += 1
        if self._held is None and f.reorder_rate and rng.random() < f.reorder_rate:
            self._held = out
            counts["reordered"] += 1
            return []
        return self._release(out)

    def _release(self, out: list[Any]) -> list[Any]:
        """``out`` followed by a frame held back for reordering."""
        if self._held is None:
            return out
        held, self._held = self._held, None
        return out + held

    def flush(self) -> list[Any]:
        """A frame still held back at the end of the stream."""
        return self._release([])

    def delay(self) -> float:
        """Extra write latency for the next frame, s."""
        if not self.faults.jitter_ms:
            return 0.0
        self.counts["delayed"] += 1
        return float(self.rng.uniform(0.0, self.faults.jitter_ms * 1e-3))

    def unplugged(self, t: float) -> bool:
        """True while trial time t is inside the unplug window."""
        at = self.faults.unplug_at_s
        return at is not None and at <= t < at + self.faults.unplug_s
