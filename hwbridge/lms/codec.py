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

How to read measured values depends on the sensor's configuration, which 0x74 requests
and 0xF4 answers (``LmsConfig``): the units (cm or mm), the measuring mode (8, 16 or
32 m: 13, 14 or 15 bits of range in each value word, flags above them) and whether each
scan carries the real-time indices, two bytes after the values: the scan counter and
the telegram counter (SICK's telegram listing 8007954, table 7-25, blocks C and D).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

STX, ACK, NAK = 0x02, 0x06, 0x15
HOST_ADDRESS = 0x00
REPLY_BIT = 0x80
MAX_LENGTH = 1024  # command + data bytes; the longest LMS 2xx telegram is under 820

# commands and their replies (command | 0x80)
MODE, REQUEST_VALUES, VARIANT, REQUEST_CONFIG = 0x20, 0x30, 0x3B, 0x74
MODE_REPLY, VALUES_REPLY, VARIANT_REPLY, CONFIG_REPLY = 0xA0, 0xB0, 0xBB, 0xF4

# operating modes (data byte of 0x20)
CONTINUOUS, STOP_CONTINUOUS = 0x24, 0x25
BAUD_MODES = {38400: 0x40, 19200: 0x41, 9600: 0x42, 500000: 0x48}
MODE_BAUDS = {v: k for k, v in BAUD_MODES.items()}
POWER_UP_BAUD = 9600

UNIT_CM, UNIT_MM = 0, 1  # the configuration's units; also bits 14-15 of the count word

# The 0xF4 reply's data, after the command byte (sicktoolbox, SickLMS2xx.cc,
# _parseSickConfigProfile): 0-1 blanking, 2 stop threshold, 3 peak threshold or
# sensitivity, 4 availability, 5 measuring mode, 6 measuring units, then fields,
# contours and restart times to byte 33; then the status byte.
CONFIG_LENGTH = 34
CONFIG_AVAILABILITY, CONFIG_MODE, CONFIG_UNITS = 4, 5, 6
# availability bit: each scan carries the real-time indices, a scan counter and a
# telegram counter, a byte each (telegram listing, table 7-122 block C, table 7-25)
REAL_TIME_INDICES = 0x02
INDEX_BYTES = 2
# Bits of range in a value word, by measuring mode (telegram listing, tables 3-7 and
# 7-28: 13, 14 and 15 bits for 8, 16 and 32 m; table 7-122 block D for the flags): 8 m
# (80 m in cm) with fields or reflector bits in the top 3 bits; 16 m, 2 flag bits; 32 m,
# 1 flag bit; 0x0F 32 m with no flags, its codes at 0x7FF7 to 0x7FFF as in the other
# 32 m modes (tables 10-15). Mode 0x05 the listing gives as 14 bits and 2 reflector bits
# in block D but as 15 bits in table 7-28; 15, as sicktoolbox reads it. 0x3F
# (reflectivity instead of range) is not a range mode.
RANGE_BITS = {0x00: 13, 0x01: 13, 0x02: 13, 0x03: 14, 0x04: 14, 0x05: 15, 0x06: 15, 0x0F: 15}
# The top values of the range field are codes, not distances (telegram listing, tables
# 10-13 to 10-15): 0x1FF7 (8183, "measured value above the maximum", what a beam that
# saw nothing reads: the 8.183 m the README quotes) to 0x1FFF (8191, no valid echo) in
# the 8 m mode; the same codes at the top of the 16 and 32 m modes' wider fields.
ERROR_CODES = 9

# A reply's status byte: bits 0-2 the sensor's state, 0 ok, 1 info, 2 warning, 3 error,
# 4 fatal error (GearBox's SICK driver, gbxsickacfr sickdefines.h, STATUS_GENERAL_MASK).
STATUS_MASK, STATUS_FATAL = 0x07, 0x04
# The count word of measured values: bits 11-12 the partial scan's index (its start at
# 0, 0.25, 0.5 or 0.75 degrees; sicktoolbox, _parseSickScanProfileB0) and bit 13 the
# partial-scan flag. A partial scan is one pass of an interlaced scan, its beams off the
# grid the count implies.
PARTIAL_BITS = 0x3800


@dataclass(frozen=True)
class LmsConfig:
    """What the measured values mean, from the sensor's configuration (0xF4)."""

    units: int = UNIT_MM
    measuring_mode: int = 0x00  # 8 m / 80 m, fields A, B and dazzle: the default
    availability: int = 0x00

    def __post_init__(self) -> None:
        if self.units not in (UNIT_CM, UNIT_MM):
            raise CodecError(f"configuration: units 0x{self.units:02X} (cm 0x00, mm 0x01)")
        if self.measuring_mode not in RANGE_BITS:
            raise CodecError(f"configuration: measuring mode 0x{self.measuring_mode:02X} "
                             "gives no ranges")

    @property
    def range_bits(self) -> int:
        return RANGE_BITS[self.measuring_mode]

    @property
    def value_mask(self) -> int:
        return (1 << self.range_bits) - 1

    @property
    def no_return(self) -> int:
        """The first code value: it and all above it mean no distance was measured."""
        return self.value_mask + 1 - ERROR_CODES

    @property
    def scale_m(self) -> float:
        return 0.001 if self.units == UNIT_MM else 0.01

    @property
    def range_max_m(self) -> float:
        """The longest range a value can carry (8.183 m in the 8 m mode in mm, 81.83 m in
        cm); a beam that saw nothing reads this."""
        return round(self.no_return * self.scale_m, 3)

    @property
    def real_time_indices(self) -> bool:
        return bool(self.availability & REAL_TIME_INDICES)


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


def request_config() -> bytes:
    """0x74: the sensor's configuration (answered by 0xF4)."""
    return build(HOST_ADDRESS, bytes([REQUEST_CONFIG]))


def variant(angle_deg: int, resolution_centideg: int) -> bytes:
    """0x3B: angular range (100 or 180 degrees) and resolution (25, 50 or 100 hundredths
    of a degree)."""
    return build(HOST_ADDRESS, bytes([VARIANT]) + angle_deg.to_bytes(2, "little")
                 + resolution_centideg.to_bytes(2, "little"))


# sensor -> host ---------------------------------------------------------------
def reply(command: int, data: bytes, status: int = 0x10, address: int = 0x80) -> bytes:
    """ACK-less reply telegram of the sensor to ``command`` (0x80 set)."""
    return build(address, bytes([command | REPLY_BIT]) + data + bytes([status]))


def encode_config(config: LmsConfig) -> bytes:
    """Device side: the data of a 0xF4 reply (the fields we do not read left 0)."""
    data = bytearray(CONFIG_LENGTH)
    data[CONFIG_AVAILABILITY] = config.availability
    data[CONFIG_MODE] = config.measuring_mode
    data[CONFIG_UNITS] = config.units
    return bytes(data)


def decode_config(data: bytes) -> LmsConfig:
    """The configuration in a 0xF4 reply's data (status byte included)."""
    if len(data) < CONFIG_UNITS + 2:
        raise CodecError(f"configuration: {len(data)} bytes")
    return LmsConfig(data[CONFIG_UNITS], data[CONFIG_MODE], data[CONFIG_AVAILABILITY])


@dataclass(frozen=True)
class MeasuredValues:
    """A 0xB0 reply, read by the configuration: raw range values (flags masked off)."""

    values: list[int]
    unit: int  # the count word's unit bits
    status: int
    real_time_index: int | None = None  # the scan counter (mod 256), if configured
    telegram_index: int | None = None  # the telegram counter (mod 256), if configured
    partial: int = 0  # bits 11-13 of the count word, shifted down: 0 for a whole scan

    @property
    def fatal(self) -> bool:
        return self.status & STATUS_MASK == STATUS_FATAL


def encode_values(values: list[int], config: LmsConfig | None = None,
                  real_time_index: int = 0, partial: int = 0,
                  telegram_index: int = 0) -> bytes:
    """Data of a 0xB0 reply: count word (count in bits 0-9, partial scan in 11-13, unit in
    14-15), values and, if the configuration asks for them, the real-time indices: the
    scan counter, then the telegram counter (no status byte)."""
    config = config or LmsConfig()
    if len(values) > 0x3FF or not 0 <= partial <= 7:
        raise CodecError("too many values, or a partial scan index past 7")
    word = len(values) | (partial << 11) | (config.units << 14)
    out = bytearray(word.to_bytes(2, "little"))
    for v in values:
        out += (v & 0xFFFF).to_bytes(2, "little")
    if config.real_time_indices:
        out += bytes([real_time_index & 0xFF, telegram_index & 0xFF])
    return bytes(out)


def decode_values(data: bytes, config: LmsConfig | None = None) -> MeasuredValues:
    """A 0xB0 reply's data (status byte included), read as ``config`` says."""
    config = config or LmsConfig()
    extra = INDEX_BYTES if config.real_time_indices else 0
    if len(data) < 3 + extra:
        raise CodecError("measured values: too short")
    word = int.from_bytes(data[0:2], "little")
    count, unit = word & 0x3FF, (word >> 14) & 0x3
    if len(data) != 2 + 2 * count + extra + 1:
        raise CodecError(f"measured values: {count} announced, {len(data)} bytes")
    mask = config.value_mask
    vals = [int.from_bytes(data[2 + 2 * j : 4 + 2 * j], "little") & mask
            for j in range(count)]
    rt, tg = (data[-3], data[-2]) if extra else (None, None)
    return MeasuredValues(vals, unit, data[-1], rt, tg, (word & PARTIAL_BITS) >> 11)


def values_to_ranges(raw: list[int], config: LmsConfig | None = None) -> list[float]:
    """Ranges in metres; the codes (no return, dazzle, ...) read ``config.range_max_m``."""
    config = config or LmsConfig()
    scale, no_return, rmax = config.scale_m, config.no_return, config.range_max_m
    return [rmax if v >= no_return else v * scale for v in raw]


def ranges_to_values(ranges_m: list[float], config: LmsConfig | None = None) -> list[int]:
    """Device side: raw values of ranges (an infinite or too long range: no return)."""
    config = config or LmsConfig()
    per_m = 1.0 / config.scale_m
    out = []
    for r in ranges_m:
        if not math.isfinite(r) or round(r * per_m) >= config.no_return:
            out.append(config.no_return)
        else:
            out.append(max(0, int(round(r * per_m))))
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
