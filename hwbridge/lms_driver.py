"""One SICK LMS 2xx on a serial port: transport + telegram codec + scan geometry, no bus.

Start-up: find the sensor at 9600 baud (its power-up rate) or already at the target
rate (the rate it answered at last, first, after a reconnect), stop continuous output,
switch to the target baud (38400 by default; 500000 needs RS-422) and let the line settle,
select the 180 degree / 0.5 degree variant, read the configuration (0x74: units, 8/16/32 m
mode, real-time indices; it says how to read every scan, and the longest range, which the
bridge publishes as range_max), start continuous output. Scans whose status says the
sensor has a fatal error, and partial scans, are dropped and counted. Every request waits
as long as the sensor may take to answer, on a line cleared of what came before it.
``poll`` returns the scans that arrived, in metres. A lost port is reopened on a backoff
and the start-up runs again.
"""

from __future__ import annotations

import logging
import time

from hwbridge.lms import codec as lms
from hwbridge.lms.model import ScanGeometry
from hwbridge.transport import PortError, SerialTransport

log = logging.getLogger("btrack.bridge.lms")

# How long the sensor may take to answer (sicktoolbox, SickLMS2xx.hh): 1 s for a request
# (DEFAULT_SICK_LMS_2XX_SICK_MESSAGE_TIMEOUT), up to 3 s for a mode change, which a baud
# change is too (..._SWITCH_MODE_TIMEOUT: "can take ... up to 3 seconds to reply").
REPLY_TIMEOUT_S = 1.0
MODE_TIMEOUT_S = 3.0
# After a baud change the host waits before it talks at the new rate (sicktoolbox,
# SickLMS2xx::_setSessionBaud sleeps 250 ms: "Sick likes a sleep here").
BAUD_SETTLE_S = 0.25


class LmsError(Exception):
    """The sensor does not answer as an LMS 2xx should."""


FRAME_BYTES = 7  # a telegram's STX, address, length, command and CRC

class LmsDriver:
    def __init__(self, port: str, baud: int = 38400,
                 geometry: ScanGeometry | None = None) -> None:
        if baud not in lms.BAUD_MODES:
            raise LmsError(f"the LMS has no {baud} baud mode (9600, 19200, 38400, 500000)")
        self.target_baud = baud
        self.geometry = geometry or ScanGeometry()
        self.config = lms.LmsConfig()  # until the sensor's is read at start-up
        self.transport = SerialTransport(port, lms.POWER_UP_BAUD)
        self.parser = lms.TelegramParser(expect_reply=True)
        self.scans = 0
        self.telegram_bytes = 0  # the last scan's telegram, framing included
        self.bad_scans = 0
        self.fatal_scans = 0  # dropped: the sensor's status said "fatal error"
        self.partial_scans = 0  # dropped: one pass of an interlaced scan, not a scan
        self.restarts = 0
        self._was_open = False
        self._answered_at: int | None = None  # the baud it last answered at
        self._units_warned = False

    @property
    def range_max_m(self) -> float:
        """The longest range the sensor's configuration can report; no return reads this."""
        return self.config.range_max_m
    @property
    def serial_errors(self) -> int:
        s = self.parser.stats
        return s.errors + s.naks + self.bad_scans + self.transport.stats.losses

    def _clear_line(self) -> None:
        """Forget what came before this request: the bytes waiting, a partial telegram."""
        self.transport.discard_input()
        self.parser.reset()

    def _settle(self, seconds: float) -> None:
        """Let the line settle after a baud change, dropping whatever arrives meanwhile."""
        until = time.monotonic() + seconds
        while time.monotonic() < until and self.transport.is_open:
            self.transport.read()
        self._clear_line()

    def _transact(self, telegram: bytes, reply_cmd: int, timeout_s: float = REPLY_TIMEOUT_S,
                  tries: int = 3) -> lms.Telegram:
        """Send on a cleared line and wait for the reply, resending after a timeout (at most
        ``tries`` sends that time out) or a NAK (the sensor heard a garbled telegram at this
        rate: resent at once, which spends no try, up to ``tries`` times). A reply to an
        earlier request that came too late is not taken for this one's: it is cleared away
        before each send (sicktoolbox flushes the terminal buffer before every request
        too)."""
        timeouts = naks = 0
        while timeouts < tries and naks <= tries:
            self._clear_line()
            if not self.transport.write(telegram):
                raise LmsError("port lost during start-up")
            deadline = time.monotonic() + timeout_s
            nak = False
            while not nak and time.monotonic() < deadline:
                for item in self.parser.feed(self.transport.read()):
                    if item == lms.NAK:
                        nak = True
                        break
                    if isinstance(item, lms.Telegram) and item.command == reply_cmd:
                        return item
                if not self.transport.is_open:
                    raise LmsError("port lost during start-up")
            if nak:
                naks += 1
            else:
                timeouts += 1
        raise LmsError(f"no reply 0x{reply_cmd:02X} from the sensor")

    def _start_sensor(self) -> None:
        rates = (self._answered_at or lms.POWER_UP_BAUD, lms.POWER_UP_BAUD, self.target_baud)
        for rate in dict.fromkeys(rates):
            self.transport.set_baud(rate)
            try:
                self._transact(lms.mode_change(lms.STOP_CONTINUOUS), lms.MODE_REPLY,
                               MODE_TIMEOUT_S, tries=1)
                break
            except LmsError:
                if not self.transport.is_open:
                    raise
                continue
        else:
            raise LmsError(f"no LMS answers on {self.transport.port} at 9600 or "
                           f"{self.target_baud} baud")
        self._answered_at = self.transport.baud
        if self.transport.baud != self.target_baud:
            rep = self._transact(lms.set_baud(self.target_baud), lms.MODE_REPLY,
                                 MODE_TIMEOUT_S)
            if rep.data[:1] != b"\x00":
                raise LmsError(f"the sensor refused {self.target_baud} baud")
            self.transport.set_baud(self.target_baud)
            self._answered_at = self.target_baud
            self._settle(BAUD_SETTLE_S)
        g = self.geometry
        rep = self._transact(lms.variant(g.angle_deg, g.resolution_centideg), lms.VARIANT_REPLY)
        if rep.data[:1] != b"\x01":
            raise LmsError(f"the sensor refused the {g.angle_deg} deg / "
                           f"{g.resolution_centideg / 100:g} deg variant")
        rep = self._transact(lms.request_config(), lms.CONFIG_REPLY)
        try:
            self.config = lms.decode_config(rep.data)
        except lms.CodecError as exc:
            raise LmsError(f"the sensor's configuration cannot be used: {exc}") from None
        self._transact(lms.mode_change(lms.CONTINUOUS), lms.MODE_REPLY, MODE_TIMEOUT_S)
        self._was_open = True

    def open(self) -> None:
        """Open and start continuous output, or raise PortError / LmsError."""
        self.transport.open()
        try:
            self._start_sensor()
        except LmsError:
            self.transport.close()
            raise

    def poll(self, now: float) -> list[list[float]]:
        """Scans (ranges in m, beam 0 on the right) that arrived since the last call."""
        if not self.transport.is_open:
            if self._was_open:
                log.warning("%s lost (reopening)", self.transport.port)
                self._was_open = False
            if self.transport.reopen(now):
                self.restarts += 1
                try:
                    self._start_sensor()
                except (LmsError, PortError) as exc:
                    log.warning("restart failed: %s", exc)
                    self.transport.close()
            return []
        out: list[list[float]] = []
        for item in self.parser.feed(self.transport.read()):
            if not isinstance(item, lms.Telegram) or item.command != lms.VALUES_REPLY:
                continue
            try:
                scan = lms.decode_values(item.data, self.config)
            except lms.CodecError:
                self.bad_scans += 1
                continue
            if scan.fatal:
                self.fatal_scans += 1
                if self.fatal_scans == 1 or self.fatal_scans % 1000 == 0:
                    log.warning("the sensor reports a fatal error (status 0x%02X): its scans "
                                "are dropped (%d so far)", scan.status, self.fatal_scans)
                continue
            if scan.partial:
                self.partial_scans += 1
                if self.partial_scans == 1:
                    log.warning("the sensor sends partial scans (index bits 0x%X): they are "
                                "dropped; is it in an interlaced output mode?", scan.partial)
                continue
            if len(scan.values) != self.geometry.beams:
                self.bad_scans += 1
                continue
            if scan.unit != self.config.units and not self._units_warned:
                self._units_warned = True
                log.warning("the scans' unit bits (%d) disagree with the configuration's "
                            "units (%d); reading them as the configuration says",
                            scan.unit, self.config.units)
            out.append(lms.values_to_ranges(scan.values, self.config))
            self.scans += 1
            # STX, address, length (2), command, the data, CRC (2): for its line time
            self.telegram_bytes = FRAME_BYTES + len(item.data)
        return out

    def close(self) -> None:
        if self.transport.is_open:
            self.transport.write(lms.mode_change(lms.STOP_CONTINUOUS))
        self.transport.close()
