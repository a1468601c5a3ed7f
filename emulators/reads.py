"""The emulated devices' frames as two device readers receive them, without ports: a recording's items.

:func:`emulated_reads` emits the frames of :func:`emulators.bench.device_streams` in time order, as
:meth:`emulators.bench.Bench.pulse_loop` does unpaced, and hands each stream's frames over in reads of
``read_s`` of trial time, as a reader of the port would: one :class:`~drivers.codec.RawChunk` per
stream per read, stamped with a host time on a real-time clock (``host_t0`` plus the read's end in
trial time, so the recording replays with ``time_scale`` 1). A read returns ``READ_LATENCY_S`` after a
multiple of ``read_s`` (the IMU's) or half a read later (the table's), so the two streams interleave as
two independent readers' do. Everything is computed as it is emitted: a trial of any length takes a
few reads of memory.
"""

from __future__ import annotations

from collections.abc import Iterator

from drivers.codec import RawChunk
from emulators.bench import device_streams
from hil.config import Config
from hil.vocabulary import Port, Stream

HOST_T0 = 1.7e9  # s, a host clock's epoch time at trial time 0
READ_LATENCY_S = 1e-3  # a read ends this long after the last frame it holds could have been written
STREAM_NAMES = {Port.IMU: Stream.IMU, Port.TABLE_DATA: Stream.TABLE}  # device -> the stream the harness records


def emulated_reads(cfg: Config, duration: float, read_s: float = 0.1, host_t0: float = HOST_T0
                   ) -> Iterator[RawChunk]:
    """The frames of a ``duration`` s run of ``cfg``'s emulated devices in reads of ``read_s``, in the
    order of their host times."""
    servo, streams = device_streams(cfg, duration)
    if streams[Port.IMU].source.codec.link != "serial":
        raise ValueError("emulated_reads: the IMU's frames are CAN frames, not a byte stream")
    buffers = {name: bytearray() for name in streams}
    phase = {Port.IMU: READ_LATENCY_S, Port.TABLE_DATA: 0.5 * read_s + READ_LATENCY_S}
    reads = dict.fromkeys(streams, 1)  # each stream's current read: it ends at reads * read_s + phase

    def end(name: str) -> float:
        return reads[name] * read_s + phase[name]

    def read(name: str) -> Iterator[RawChunk]:
        """The stream's current read (none when it holds no bytes), and the next one started."""
        if buffers[name]:
            yield RawChunk(STREAM_NAMES[name], host_t0 + end(name), bytes(buffers[name]))
            buffers[name].clear()
        reads[name] += 1

    while True:
        live = [name for name, s in streams.items() if not s.done()]
        if not live:
            break
        name = min(live, key=lambda n: streams[n].next_time())
        t = streams[name].next_time()
        while end(first := min(reads, key=end)) < t:  # the reads that end before t, in order
            yield from read(first)
        servo.advance(t)
        emission = streams[name].pop(servo)
        servo.commit(emission.latest)
        if emission.powered and (name != Port.TABLE_DATA or servo.sync_output):
            buffers[name] += emission.payload
    for name in sorted(reads, key=end):  # the last reads
        yield from read(name)
