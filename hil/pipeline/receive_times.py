"""The receive times of the sync pairing (:mod:`hil.pipeline.sync_pairing`): each read's lateness, the coarse
offset they give, and the tolerance its watch allows.

The newest frame of a read left its device a frame's wire time before it arrived, plus a latency that is small
for the freshest reads. Per read, ``e = R (h - h_ref) - R wire - counter`` (pulses; R the pulse rate on the host's
clock) is the stream's lateness less its offset; its minimum over many reads, against the other stream's
baseline, gives the offset to within the reads' jitter. At ``--speed max`` (no host rate) the host times say
nothing of the devices', and the coarse offset is the difference of the streams' first counters.
"""

from __future__ import annotations

from hil.pipeline.pairing_streams import MIN_READS, StreamPairing

MIN_TOLERANCE_S = 0.003  # host seconds: the least lateness the watch allows for
JITTER_FACTOR = 3.0  # the watch allows this many times the reads' spread (90th percentile over minimum)
STILL_S = 1.0  # of a stream's samples held before its receive times alone may pair it


class ReceiveTimes:
    """The receive-time side of pairing the ``imu`` and ``table`` streams: ``host_rate`` is the pulse rate on
    the host's clock (None: unpaced), ``imu_modulus`` the IMU counter's (None: no counter). :attr:`failure`
    says why the counters cannot be paired at all."""

    def __init__(self, host_rate: float | None, imu: StreamPairing, table: StreamPairing,
                 imu_modulus: int | None) -> None:
        self.host_rate = host_rate
        self.imu = imu
        self.table = table
        self.imu_modulus = imu_modulus
        self.failure: str | None = None
        self._h_ref: float | None = None

    def lateness(self, s: StreamPairing, h: float, counter: int) -> float:
        """Pulses from the newest frame's pulse (less the stream's offset) to its arrival at ``h``: ``e``."""
        if self._h_ref is None:
            self._h_ref = h
        if self.host_rate is None:
            return 0.0
        return self.host_rate * (h - self._h_ref) - s.wire - counter

    def jitter(self, quantile: float = 0.9) -> float:
        """Pulses the reads' lateness scatters by (its ``quantile`` over its least, the worse stream's)."""
        return max(self.imu.spread(quantile), self.table.spread(quantile))

    def tolerance(self) -> float:
        """Pulses of lateness the watch allows: ``JITTER_FACTOR`` times the jitter, at least ``MIN_TOLERANCE_S``."""
        return max(2.0, MIN_TOLERANCE_S * self.host_rate, JITTER_FACTOR * self.jitter())

    def backlog(self, s: StreamPairing) -> float:
        """Pulses by which the segment's reads were late at worst against their least: after a stall of the
        host its first reads bring old frames, and the least lateness may not yet be a prompt read's."""
        late = [e for _, e in s.segment]
        return max(late) - min(late) + self.tolerance()

    def offset(self, s: StreamPairing, coarse: int) -> int:
        """The offset by receive time alone: the one before the break where the receive times cannot tell them
        apart (a host that was late broke it, not the device)."""
        if s.offset_before is not None and self.host_rate is not None and abs(coarse - s.offset_before) <= \
                self.tolerance():
            return s.offset_before
        return coarse

    def coarse(self, s: StreamPairing, rate: float, table_first: int | None) -> int | None:
        """The offset the receive times give (None until they can); unpaced, the difference of the streams' first
        counters (``table_first`` the table's first pulse)."""
        if self.host_rate is None:
            if s.offset_before is not None:
                return s.offset_before  # reconnected: the unwrapped count carries on, unless the device restarted
            return None if table_first is None or s.first is None else table_first - s.first
        if len(s.segment) < MIN_READS and s.waited(rate) < STILL_S:
            return None
        other = self.table if s is self.imu else self.imu
        baseline = s.baseline(1)
        if baseline is None:
            baseline = other.baseline(1) if other.offset is not None else None
        if baseline is None:
            return None
        jitter = self.jitter(0.5)  # the least lateness is found while half the reads are prompt
        if s is self.imu and self.imu_modulus and jitter >= self.imu_modulus / 2:
            jitter_ms, half_ms = (1e3 * x / self.host_rate for x in (jitter, self.imu_modulus / 2))
            self.failure = (f"the receive times scatter by {jitter_ms:.0f} ms, more than half the IMU counter's "
                            f"period ({half_ms:.0f} ms): its counter cannot be paired with the table's; read the "
                            f"ports faster (a lower-latency host or adapter), lower imu.rate_hz, or use a device "
                            f"with a wider counter")
            return None
        return round(min(e for _, e in s.segment) - baseline)
