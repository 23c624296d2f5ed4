#!/usr/bin/env python3
"""How late a pseudo-terminal's bytes arrive on this machine, now.

Writes a timestamp into a pseudo-terminal every 10 ms from one thread and
reads it back from another, polling the way trailnav's serial links do
(FIONREAD, then read; no blocking read), and prints the p50, p99 and worst
delay. Run it beside whatever load is in question (docs/testing.md, "Loaded
machine"): the bench's serial sensors (GPS, IMU) travel this path.

Usage: toolchain/pty-latency.py [--seconds S]   (default 30)
"""
import argparse
import fcntl
import os
import pty
import struct
import termios
import threading
import time
import tty


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="how long to measure (default 30)")
    args = parser.parse_args()
    if args.seconds <= 0:
        parser.error("--seconds must be positive")
    master, slave = pty.openpty()
    tty.setraw(slave)
    stop = time.monotonic() + args.seconds

    def writer() -> None:
        while time.monotonic() < stop:
            os.write(master, struct.pack("d", time.monotonic()))
            time.sleep(0.01)

    threading.Thread(target=writer, daemon=True).start()
    pending = b""
    delays = []
    while time.monotonic() < stop:
        available = struct.unpack("i", fcntl.ioctl(slave, termios.FIONREAD, b"\0\0\0\0"))[0]
        if available > 0:
            pending += os.read(slave, available)
            now = time.monotonic()
            while len(pending) >= 8:
                delays.append(now - struct.unpack("d", pending[:8])[0])
                pending = pending[8:]
        time.sleep(0.002)
    if not delays:
        print("pty-latency: nothing came back")
        return 1
    delays.sort()
    ms = lambda q: delays[min(len(delays) - 1, int(q * len(delays)))] * 1e3
    print(f"pty-latency: {len(delays)} writes; delay p50 {ms(0.5):.1f} ms, p99 {ms(0.99):.1f} ms, worst {delays[-1] * 1e3:.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
