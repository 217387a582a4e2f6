"""Emulated devices on real pseudo-terminals.

``PtyPort`` owns a pty pair and a stable symlink to its slave (like udev's
``/dev/serial/by-id`` names), which the bridge opens with pyserial; ``unplug`` closes
the pair (the bridge's reads fail as with a pulled USB adapter) and ``plug`` makes a new
one behind the same name. ``CreateEmulator`` and ``LmsEmulator`` run a device core
(``devices.py``) on a thread: they answer commands, send the Create's stream every
15 ms, and send the LMS's scans no faster than the mirror (75 Hz, two turns per
interlaced 0.5 degree scan) and the line (10 bits per byte at the current baud) allow.
``Faults`` corrupts the device's output on purpose, from a seed, to test resync. With
``check_baud`` an emulator reads the baud rate the host set on the terminal and, when it
is not the device's, hears the host's bytes as garbage and sends garbage, as a real
serial line does (a pty on its own carries bytes whatever the rate).
"""

from __future__ import annotations

import collections
import contextlib
import errno
import os
import random
import select
import termios
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from hwbridge.create.model import ModelSpec
from hwbridge.emulators.devices import CreateDevice, LmsDevice, PowerPlan
from hwbridge.lms.codec import LmsConfig

# termios speed codes of the rates the devices use
_SPEEDS = {rate: getattr(termios, f"B{rate}", None)
           for rate in (9600, 19200, 38400, 57600, 115200, 500000)}

CREATE_FRAME_S = 0.015
LMS_SCAN_S = 2.0 / 75.0  # interlaced 0.5 degree scan: two mirror turns


class PtyPort:
    def __init__(self, link: str | Path) -> None:
        self.link = Path(link)
        self.master = -1
        self.slave = -1
        self.dropped_bytes = 0  # written while the line was full (nobody reading)
        self.plug()

    @property
    def plugged(self) -> bool:
        return self.master >= 0

    def plug(self) -> None:
        if self.plugged:
            return
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing: bytes pass unchanged
        os.set_blocking(master, False)
        self.master, self.slave = master, slave
        tmp = self.link.with_name(self.link.name + ".tmp")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        tmp.symlink_to(os.ttyname(slave))
        os.replace(tmp, self.link)

    def unplug(self) -> None:
        for fd in (self.master, self.slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master = self.slave = -1

    def close(self) -> None:
        self.unplug()
        with contextlib.suppress(FileNotFoundError):
            self.link.unlink()

    def read(self, timeout_s: float) -> bytes:
        if not self.plugged:
            time.sleep(timeout_s)
            return b""
        fd = self.master
        try:  # unplug() may close fd from another thread at any moment
            ready, _, _ = select.select([fd], [], [], max(0.0, timeout_s))
            return os.read(fd, 4096) if ready else b""
        except (OSError, ValueError) as exc:
            if isinstance(exc, ValueError) or exc.errno in (errno.EAGAIN, errno.EIO, errno.EBADF):
                return b""
            raise

    def host_speed(self) -> int | None:
        """The termios speed code the host set on its end of the line (None: unknown)."""
        try:
            return termios.tcgetattr(self.slave)[5] if self.plugged else None
        except (termios.error, OSError):
            return None

    def write(self, data: bytes) -> None:
        if not self.plugged:
            return
        try:
            n = os.write(self.master, data)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EIO, errno.EBADF):
                raise
            n = 0
        self.dropped_bytes += len(data) - n


@dataclass
class Faults:
    """Damage done to the device's output, each with its probability per message."""

    garbage: float = 0.0  # random bytes before the message
    corrupt: float = 0.0  # one byte of the message flipped
    truncate: float = 0.0  # the message cut short
    seed: int = 0
    injected: int = 0
    _rng: random.Random = field(init=False)

    def __post_init__(self) -> None:
        self._rng = random.Random(self.seed)

    def apply(self, msg: bytes) -> bytes:
        rng = self._rng
        out = msg
        if self.corrupt and rng.random() < self.corrupt:
            b = bytearray(out)
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
            out = bytes(b)
            self.injected += 1
        if self.truncate and rng.random() < self.truncate:
            out = out[: rng.randrange(1, len(out))]
            self.injected += 1
        if self.garbage and rng.random() < self.garbage:
            out = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 20))) + out
            self.injected += 1
        return out


class _Emulator:
    def __init__(self, link: str | Path, faults: Faults | None,
                 check_baud: bool = False) -> None:
        self.port = PtyPort(link)
        self.faults = faults or Faults()
        self.check_baud = check_baud
        self.lock = threading.Lock()
        self.bytes_out = 0
        self.bytes_in = 0
        self.garbled_bytes = 0  # crossed the line at a rate the other end was not at
        self._noise = random.Random(0x5EED)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _device_baud(self) -> int:  # pragma: no cover - overridden
        raise NotImplementedError

    def _rates_differ(self) -> bool:
        if not self.check_baud:
            return False
        host = self.port.host_speed()
        with self.lock:
            device = _SPEEDS.get(self._device_baud())
        return host is not None and device is not None and host != device

    def _hear(self, data: bytes) -> bytes:
        """What the device makes of the host's bytes: nothing, at the wrong rate."""
        if data and self._rates_differ():
            self.garbled_bytes += len(data)
            return b""
        return data

    @property
    def path(self) -> str:
        return str(self.port.link)

    def start(self) -> _Emulator:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.port.close()

    def _send(self, data: bytes, damage: bool = True) -> None:
        if damage:
            data = self.faults.apply(data)
        if self._rates_differ():
            self.garbled_bytes += len(data)
            data = bytes(self._noise.randrange(256) for _ in data)
        self.port.write(data)
        self.bytes_out += len(data)

    def _run(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError


class CreateEmulator(_Emulator):
    """An iRobot Create (or Create 2) on a pty. ``plan`` makes it asleep, switched on late
    or rebooting (``devices.PowerPlan``; times from ``start``); ``drop_remainder`` makes its
    odometry packets truncate as the original Create's do; ``moves`` makes it drive itself
    at its wheel speeds each stream period (for tests without the simulator's physics)."""

    def __init__(self, link: str | Path, spec: ModelSpec, faults: Faults | None = None, *,
                 plan: PowerPlan | None = None, drop_remainder: bool = False,
                 moves: bool = False, check_baud: bool = False) -> None:
        super().__init__(link, faults, check_baud)
        self.device = CreateDevice(spec, plan=plan or PowerPlan(),
                                   drop_remainder=drop_remainder)
        self.moves = moves
        self.frames = 0
        self.received = bytearray()  # every byte the host sent, for tests to read

    def _device_baud(self) -> int:
        return self.device.baud

    def _run(self) -> None:
        started = next_frame = time.monotonic()
        while not self._stop.is_set():
            data = self._hear(self.port.read(max(0.0, next_frame - time.monotonic())))
            if data:
                self.bytes_in += len(data)
                with self.lock:
                    self.received += data
                    answer = self.device.receive(data)
                if answer:
                    self._send(answer, damage=False)
            now = time.monotonic()
            if now >= next_frame:
                next_frame += CREATE_FRAME_S
                if now > next_frame:  # fell behind (a loaded machine): do not burst
                    next_frame = now + CREATE_FRAME_S
                with self.lock:
                    printed = self.device.advance(now - started)
                    if self.moves:
                        self.device.roll(CREATE_FRAME_S)
                    frame = self.device.stream_frame()
                if printed:
                    self._send(printed, damage=False)
                if frame is not None and self.port.plugged:
                    self._send(frame)
                    self.frames += 1


class LmsEmulator(_Emulator):
    """A SICK LMS 2xx on a pty; ``ranges`` gives the scene's current ranges;
    ``reply_latency_s`` how late it answers which telegrams, ``config`` its units, range
    mode and real-time indices (``devices.LmsDevice``)."""

    def __init__(self, link: str | Path, ranges: Callable[[], list[float]] | None = None,
                 faults: Faults | None = None, *,
                 reply_latency_s: dict[bytes, float] | None = None,
                 config: LmsConfig | None = None, check_baud: bool = False) -> None:
        super().__init__(link, faults, check_baud)
        self.device = LmsDevice(config=config or LmsConfig(),
                                reply_latency_s=dict(reply_latency_s or {}))
        self.ranges = ranges
        self.scans = 0

    def _device_baud(self) -> int:
        return self.device.baud

    def _run(self) -> None:
        line_free = time.monotonic()  # when the line has sent what we wrote
        next_scan = time.monotonic()
        pending: collections.deque[tuple[float, bytes, int | None]] = collections.deque()
        # A scan's telegram reaches the host whole only once its last byte has crossed
        # the line, its line time after the scan: a pty passes bytes at once, so it is
        # held until then (the host stamps a scan's time from its arrival).
        on_line: collections.deque[tuple[float, bytes]] = collections.deque()
        while not self._stop.is_set():
            now = time.monotonic()
            while on_line and now >= on_line[0][0]:
                if self.port.plugged:
                    self._send(on_line.popleft()[1])
                    self.scans += 1
                else:
                    on_line.popleft()
            wait = max(0.0, min(0.02, next_scan - now)) if self.device.continuous else 0.02
            if pending:
                wait = max(0.0, min(wait, pending[0][0] - now))
            if on_line:
                wait = max(0.0, min(wait, on_line[0][0] - now))
            data = self._hear(self.port.read(wait))
            if data:
                self.bytes_in += len(data)
                with self.lock:
                    replies = self.device.receive(data)
                now = time.monotonic()
                for r in replies:  # in order: none overtakes a late one before it
                    due = max(now + r.delay_s, pending[-1][0] if pending else 0.0)
                    pending.append((due, r.data, r.baud_after))
            while pending and time.monotonic() >= pending[0][0]:
                _, answer, baud_after = pending.popleft()
                with self.lock:
                    baud = self.device.baud
                self._send(answer, damage=False)  # at the old baud...
                line_free = max(line_free, time.monotonic()) + len(answer) * 10.0 / baud
                if baud_after is not None:
                    with self.lock:
                        self.device.baud = baud_after  # ...then the switch
            now = time.monotonic()
            if (self.device.continuous and not pending
                    and now >= max(next_scan, line_free)):
                if self.ranges is not None:
                    self.device.ranges_m = self.ranges()
                with self.lock:
                    tel = self.device.values_telegram()
                    baud = self.device.baud
                line_free = now + len(tel) * 10.0 / baud
                on_line.append((line_free, tel))
                next_scan = now + LMS_SCAN_S
