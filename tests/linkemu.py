"""A userspace link emulator for the multi-host tests: pairs of TAP devices joined
by this process, which forwards every Ethernet frame after a fixed delay and drops a
fraction of them, in both directions (what ``tc netem delay D loss L`` on both ends
of a veth would do; that qdisc is missing from some kernels, this one's included).

Run as root: ``python tests/linkemu.py A1 B1 [A2 B2 ...]`` creates the TAP devices
(the test then moves them into namespaces), prints ``ready`` and reads commands on
stdin, one a line, answering ``ok`` to each: ``set DELAY_MS LOSS`` for every link,
``set PAIR DELAY_MS LOSS`` for one (PAIR 0-based). It ends on EOF or SIGTERM.
Frames keep their order; the delay is constant and the loss independent per frame.
"""

from __future__ import annotations

import fcntl
import heapq
import os
import random
import select
import signal
import struct
import sys
import time

TUNSETIFF = 0x400454CA
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000


def open_tap(name: str) -> int:
    fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
    fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH", name.encode(), IFF_TAP | IFF_NO_PI))
    return fd


def main(argv: list[str]) -> int:
    if not argv or len(argv) % 2:
        print(__doc__, file=sys.stderr)
        return 2
    names = list(zip(argv[::2], argv[1::2], strict=True))
    peer: dict[int, tuple[int, int]] = {}  # fd -> (fd it forwards to, pair index)
    for i, (a, b) in enumerate(names):
        fa, fb = open_tap(a), open_tap(b)
        peer[fa], peer[fb] = (fb, i), (fa, i)
    params = [(0.0, 0.0)] * len(names)  # (delay s, loss) per pair
    rng = random.Random(os.getpid())
    queue: list[tuple[float, int, int, bytes]] = []  # (due, seq, fd, frame)
    seq = 0
    running = True

    def stop(*_: object) -> None:
        nonlocal running
        running = False

    signal.signal(signal.SIGTERM, stop)
    print("ready", flush=True)
    stdin = sys.stdin.fileno()
    buf = b""
    while running:
        now = time.monotonic()
        while queue and queue[0][0] <= now:
            _, _, fd, frame = heapq.heappop(queue)
            try:
                os.write(fd, frame)
            except OSError:
                pass  # the device is down: the frame is lost, as on a cut cable
        timeout = max(0.0, queue[0][0] - now) if queue else 0.5
        try:
            ready, _, _ = select.select([stdin, *peer], [], [], timeout)
        except InterruptedError:
            continue
        for fd in ready:
            if fd == stdin:
                chunk = os.read(stdin, 4096)
                if not chunk:
                    return 0
                buf += chunk
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    words = line.decode().split()
                    if len(words) == 3:
                        params = [(float(words[1]) / 1000.0, float(words[2]))] * len(names)
                    elif len(words) == 4:
                        params[int(words[1])] = (float(words[2]) / 1000.0, float(words[3]))
                    print("ok", flush=True)
                continue
            while True:
                try:
                    frame = os.read(fd, 65536)
                except (BlockingIOError, OSError):
                    break
                dst, pair = peer[fd]
                delay, loss = params[pair]
                if loss and rng.random() < loss:
                    continue
                seq += 1
                heapq.heappush(queue, (time.monotonic() + delay, seq, dst, frame))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
