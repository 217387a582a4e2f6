"""Bytes in and out of a serial port (pyserial), and reopening it when it is lost.

A USB serial adapter that is unplugged makes reads and writes fail; ``SerialTransport``
then closes the port, counts the loss and lets the caller retry ``reopen`` on a
backoff (0.2 s doubling to 2 s). The caller passes the time, so the backoff is testable.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import serial

log = logging.getLogger("btrack.transport")


class PortError(Exception):
    """The port cannot be opened at all (bad path, permissions): a clear message."""


@dataclass
class TransportStats:
    bytes_in: int = 0
    bytes_out: int = 0
    opens: int = 0
    losses: int = 0
    failed_opens: int = 0


class SerialTransport:
    BACKOFF_MIN_S = 0.2
    BACKOFF_MAX_S = 2.0

    def __init__(self, port: str, baud: int, read_timeout_s: float = 0.01) -> None:
        self.port = port
        self.baud = baud
        self.read_timeout_s = read_timeout_s
        self.stats = TransportStats()
        self._serial: serial.Serial | None = None
        self._next_try = 0.0
        self._backoff = self.BACKOFF_MIN_S

    @property
    def is_open(self) -> bool:
        return self._serial is not None

    def open(self) -> None:
        """Open now, or raise ``PortError`` with the reason."""
        try:
            self._serial = serial.Serial(self.port, self.baud, timeout=self.read_timeout_s,
                                         write_timeout=1.0)
        except (serial.SerialException, OSError, ValueError) as exc:
            self._serial = None
            raise PortError(f"cannot open {self.port}: {exc}") from None
        self.stats.opens += 1
        self._backoff = self.BACKOFF_MIN_S

    def reopen(self, now: float) -> bool:
        """Try to open a lost port if its backoff has passed; True when it is open."""
        if self._serial is not None:
            return True
        if now < self._next_try:
            return False
        try:
            self.open()
        except PortError as exc:
            self.stats.failed_opens += 1
            self._next_try = now + self._backoff
            self._backoff = min(self.BACKOFF_MAX_S, 2 * self._backoff)
            log.debug("%s", exc)
            return False
        log.warning("%s reopened", self.port)
        return True

    def _lost(self, exc: Exception) -> None:
        if self._serial is not None:
            log.warning("%s lost: %s", self.port, exc)
            self.stats.losses += 1
            try:
                self._serial.close()
            except Exception:  # the device is already gone
                pass
        self._serial = None
        self._next_try = 0.0

    def read(self) -> bytes:
        """What arrived within the read timeout; b"" when closed or lost."""
        if self._serial is None:
            return b""
        try:
            first = self._serial.read(1)
            if not first:
                return b""
            waiting = self._serial.in_waiting
            data = first + (self._serial.read(waiting) if waiting else b"")
        except (serial.SerialException, OSError) as exc:
            self._lost(exc)
            return b""
        self.stats.bytes_in += len(data)
        return data

    def write(self, data: bytes) -> bool:
        if self._serial is None:
            return False
        try:
            self._serial.write(data)
        except (serial.SerialException, OSError) as exc:
            self._lost(exc)
            return False
        self.stats.bytes_out += len(data)
        return True

    def discard_input(self) -> None:
        """Throw away what arrived and was not read yet (a reply to an earlier request)."""
        if self._serial is not None:
            try:
                self._serial.reset_input_buffer()
            except (serial.SerialException, OSError) as exc:
                self._lost(exc)

    def set_baud(self, baud: int) -> None:
        self.baud = baud
        if self._serial is not None:
            try:
                self._serial.baudrate = baud
            except (serial.SerialException, OSError, ValueError) as exc:
                self._lost(exc)

    def close(self) -> None:
        if self._serial is not None:
            try:
                self._serial.close()
            except Exception:
                pass
        self._serial = None
