"""The floor under a live read: CPU of a loop that only reads two ports on a grid and writes the bytes to a file.

A child process writes a 36-byte and a 24-byte frame (a KVH 1750's and a TTS1's) to two pseudo-terminals
at ``--rate``; this process wakes on a grid of ``--period`` s, reads what both have and appends it to a
file, with nothing decoded. What it costs is what any harness on this interpreter pays to read that often,
before the first frame is looked at.

    .venv/bin/python benchmarks/read_floor.py [--period 0.015] [--duration 20] [--rate 200]
"""

from __future__ import annotations

import argparse
import os
import pty
import resource
import subprocess
import sys
import tempfile
import time
import tty

WRITER = """
import os, sys, time
fds, rate, duration = [int(f) for f in sys.argv[1].split(",")], float(sys.argv[2]), float(sys.argv[3])
frames = (b"x" * 36, b"y" * 24)
t0, k = time.monotonic(), 0
while time.monotonic() - t0 < duration:
    k += 1
    for fd, frame in zip(fds, frames):
        os.write(fd, frame)
    time.sleep(max(0.0, t0 + k / rate - time.monotonic()))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--period", type=float, default=0.015, help="s between reads")
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--rate", type=float, default=200.0, help="frames a second on each port")
    args = parser.parse_args()
    ports = [pty.openpty() for _ in range(2)]
    for controller, device in ports:
        tty.setraw(device)
        os.set_blocking(controller, False)
    devices = [device for _, device in ports]
    writer = subprocess.Popen([sys.executable, "-c", WRITER, ",".join(map(str, devices)), str(args.rate),
                               str(args.duration)], pass_fds=devices)
    received = 0
    with tempfile.TemporaryFile() as out:
        before, start = resource.getrusage(resource.RUSAGE_SELF), time.monotonic()
        while time.monotonic() - start < args.duration:
            time.sleep(args.period - time.monotonic() % args.period)
            for controller, _ in ports:
                try:
                    data = os.read(controller, 65536)
                except BlockingIOError:  # nothing has arrived
                    continue
                out.write(data)
                received += len(data)
            out.flush()
        after = resource.getrusage(resource.RUSAGE_SELF)
    writer.wait()
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    print(f"reads every {args.period * 1e3:g} ms for {args.duration:g} s: {100 * cpu / args.duration:.2f} % of one core, "
          f"{1e6 * cpu * args.period / args.duration:.0f} us a read of both ports, {received} bytes")


if __name__ == "__main__":
    main()
