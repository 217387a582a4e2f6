"""SICK LMS 2xx serial telegrams, both directions, with no I/O and no clock.

A telegram is STX 0x02, an address (0x00 to the sensor, 0x80 set in replies), a 16-bit
little-endian length of command byte plus data (a reply's data ends with a status
byte), the command, the data and a 16-bit little-endian CRC over everything from STX.
The sensor first answers each telegram with ACK 0x06 (or NAK 0x15 for a corrupt one).

The CRC is SICK's 16-bit scheme with generator 0x8005: for each byte, the running CRC
shifts left one bit (xor 0x8005 when its top bit was set), then is xored with the
16-bit word (previous byte << 8 | this byte). Checked here against telegrams published
with their CRC: ``02 00 02 00 20 24 | 34 08`` (continuous output),
``02 00 02 00 20 25 | 35 08`` (stop it), ``02 00 02 00 30 01 | 31 18`` (one scan),
``02 00 02 00 20 42 | 52 08`` (9600 baud) and the reply
``02 80 03 00 A0 00 10 | 16 0A`` (mode change accepted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

STX, ACK, NAK = 0x02, 0x06, 0x15
HOST_ADDRESS = 0x00
REPLY_BIT = 0x80
MAX_LENGTH = 1024  # command + data bytes; the longest LMS 2xx telegram is under 820

# commands and their replies (command | 0x80)
MODE, REQUEST_VALUES, VARIANT = 0x20, 0x30, 0x3B
MODE_REPLY, VALUES_REPLY, VARIANT_REPLY = 0xA0, 0xB0, 0xBB

# operating modes (data byte of 0x20)
CONTINUOUS, STOP_CONTINUOUS = 0x24, 0x25
BAUD_MODES = {38400: 0x40, 19200: 0x41, 9600: 0x42, 500000: 0x48}
MODE_BAUDS = {v: k for k, v in BAUD_MODES.items()}
POWER_UP_BAUD = 9600

UNIT_CM, UNIT_MM = 0, 1  # bits 14-15 of the measured-value count word
VALUE_MASK = 0x1FFF  # 13 bits of distance; the top bits of each word carry flags
NO_RETURN_MM = 8183  # values at or above this in mm mode mean "nothing seen"


class CodecError(ValueError):
    """A telegram that cannot be built or understood."""


def crc16(data: bytes) -> int:
    """SICK's CRC over ``data`` (generator 0x8005, previous byte folded in)."""
    crc = 0
    prev = 0
    for byte in data:
        word = (prev << 8) | byte
        prev = byte
        if crc & 0x8000:
            crc = ((crc & 0x7FFF) << 1) ^ 0x8005
        else:
            crc = (crc << 1) & 0xFFFF
        crc ^= word
    return crc


def build(address: int, payload: bytes) -> bytes:
    """A whole telegram: STX, address, length, payload (command, data[, status]), CRC."""
    if not 1 <= len(payload) <= MAX_LENGTH:
        raise CodecError(f"payload of {len(payload)} bytes")
    head = bytes([STX, address]) + len(payload).to_bytes(2, "little") + payload
    return head + crc16(head).to_bytes(2, "little")


@dataclass(frozen=True)
class Telegram:
    address: int
    command: int
    data: bytes  # after the command byte (a reply's status byte is the last)

    @property
    def is_reply(self) -> bool:
        return bool(self.address & REPLY_BIT)


# host -> sensor --------------------------------------------------------------
def mode_change(mode: int) -> bytes:
    return build(HOST_ADDRESS, bytes([MODE, mode]))


def set_baud(rate: int) -> bytes:
    if rate not in BAUD_MODES:
        raise CodecError(f"the LMS has no {rate} baud mode (9600, 19200, 38400, 500000)")
    return mode_change(BAUD_MODES[rate])


def request_values() -> bytes:
    return build(HOST_ADDRESS, bytes([REQUEST_VALUES, 0x01]))


def variant(angle_deg: int, resolution_centideg: int) -> bytes:
    """0x3B: angular range (100 or 180 degrees) and resolution (25, 50 or 100 hundredths
    of a degree)."""
    return build(HOST_ADDRESS, bytes([VARIANT]) + angle_deg.to_bytes(2, "little")
                 + resolution_centideg.to_bytes(2, "little"))


# sensor -> host ---------------------------------------------------------------
def reply(command: int, data: bytes, status: int = 0x10, address: int = 0x80) -> bytes:
    """ACK-less reply telegram of the sensor to ``command`` (0x80 set)."""
    return build(address, bytes([command | REPLY_BIT]) + data + bytes([status]))


def encode_values(values: list[int], unit: int = UNIT_MM) -> bytes:
    """Data of a 0xB0 reply: count word (count in bits 0-9, unit in 14-15), values."""
    if len(values) > 0x3FF:
        raise CodecError("too many values")
    out = bytearray((len(values) | (unit << 14)).to_bytes(2, "little"))
    for v in values:
        out += (v & 0xFFFF).to_bytes(2, "little")
    return bytes(out)


def decode_values(data: bytes) -> tuple[int, list[int]]:
    """(unit, raw 13-bit values) from a 0xB0 reply's data (status byte included)."""
    if len(data) < 3:
        raise CodecError("measured values: too short")
    word = int.from_bytes(data[0:2], "little")
    count, unit = word & 0x3FF, (word >> 14) & 0x3
    if len(data) != 2 + 2 * count + 1:
        raise CodecError(f"measured values: {count} announced, {len(data)} bytes")
    vals = [int.from_bytes(data[2 + 2 * j : 4 + 2 * j], "little") & VALUE_MASK
            for j in range(count)]
    return unit, vals


def values_to_ranges(unit: int, raw: list[int], range_max_m: float) -> list[float]:
    """Ranges in metres; no-return codes and anything past ``range_max_m`` become it."""
    scale = 0.001 if unit == UNIT_MM else 0.01
    out = []
    for v in raw:
        r = v * scale
        out.append(range_max_m if (unit == UNIT_MM and v >= NO_RETURN_MM) or r > range_max_m
                   else r)
    return out


def ranges_to_values(ranges_m: list[float], unit: int = UNIT_MM) -> list[int]:
    """Device side: raw values of ranges (an infinite or too long range: no return)."""
    scale = 1000.0 if unit == UNIT_MM else 100.0
    out = []
    for r in ranges_m:
        if not math.isfinite(r) or r * scale >= NO_RETURN_MM:
            out.append(NO_RETURN_MM if unit == UNIT_MM else min(VALUE_MASK, int(r * scale)))
        else:
            out.append(max(0, int(round(r * scale))))
    return out


def beam_count(angle_deg: int, resolution_centideg: int) -> int:
    return angle_deg * 100 // resolution_centideg + 1


@dataclass
class ParserStats:
    telegrams: int = 0
    acks: int = 0
    naks: int = 0
    bad_crc: int = 0
    bad_header: int = 0  # impossible address or length after an STX
    skipped_bytes: int = 0

    @property
    def errors(self) -> int:
        return self.bad_crc + self.bad_header


@dataclass
class TelegramParser:
    """Incremental parser of either direction. ``feed`` returns, in order, ``ACK``,
    ``NAK`` (ints) and complete ``Telegram`` objects. A bad header or CRC is counted and
    the search resumes one byte after its STX, so garbage and truncation resynchronise.

    ``expect_reply`` selects which address family is plausible (0x80 set or not)."""

    expect_reply: bool = True
    stats: ParserStats = field(default_factory=ParserStats)
    _buf: bytearray = field(default_factory=bytearray)

    def reset(self) -> None:
        self._buf.clear()

    def feed(self, data: bytes) -> list[Telegram | int]:
        buf = self._buf
        buf += data
        out: list[Telegram | int] = []
        while buf:
            b = buf[0]
            if b != STX:
                if b == ACK:
                    self.stats.acks += 1
                    out.append(ACK)
                elif b == NAK:
                    self.stats.naks += 1
                    out.append(NAK)
                else:
                    self.stats.skipped_bytes += 1
                del buf[:1]
                continue
            if len(buf) < 4:
                break
            length = int.from_bytes(buf[2:4], "little")
            if bool(buf[1] & REPLY_BIT) != self.expect_reply or not 1 <= length <= MAX_LENGTH:
                self.stats.bad_header += 1
                del buf[:1]
                continue
            total = 4 + length + 2
            if len(buf) < total:
                later = self._complete_later(buf)
                if later is None:
                    break
                # A false STX announced a long telegram; a real one is complete after it.
                self.stats.bad_header += 1
                self.stats.skipped_bytes += later - 1
                del buf[:later]
                continue
            body = bytes(buf[: 4 + length])
            if crc16(body) != int.from_bytes(buf[4 + length : total], "little"):
                self.stats.bad_crc += 1
                del buf[:1]
                continue
            del buf[:total]
            self.stats.telegrams += 1
            out.append(Telegram(body[1], body[4], body[5:]))
        return out

    def _complete_later(self, buf: bytearray) -> int | None:
        """The offset of a later STX that starts a complete telegram with a good CRC."""
        start = 1
        while True:
            i = buf.find(STX, start)
            if i < 0 or len(buf) - i < 6:
                return None
            length = int.from_bytes(buf[i + 2 : i + 4], "little")
            end = i + 4 + length + 2
            if (bool(buf[i + 1] & REPLY_BIT) == self.expect_reply and 1 <= length <= MAX_LENGTH
                    and end <= len(buf)
                    and crc16(bytes(buf[i : i + 4 + length]))
                    == int.from_bytes(buf[end - 2 : end], "little")):
                return i
            start = i + 1
