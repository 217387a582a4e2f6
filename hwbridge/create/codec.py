"""iRobot Open Interface bytes, both directions, with no I/O and no clock.

Host side: command encoders (Start, Safe, Full, Drive Direct, Stream, ...) and
``StreamParser``, an incremental parser of the sensor stream that resynchronises after
garbage. Device side (for the emulator): ``CommandParser`` and ``encode_stream_frame``.

Facts checked against the iRobot Create OI specification (2006) and the Create 2 OI
specification (2016): a stream frame is header 19, a byte count n, n bytes of
(packet id, data) pairs, and a checksum byte that makes the sum of all frame bytes 0
modulo 256; 16-bit values are big-endian; distance (19, mm) and angle (20, degrees,
counter-clockwise positive) are signed; packet 32 holds the cargo-bay digital inputs
(bit 0 = input 0, pin 17), packet 33 the cargo-bay analog input (pin 4, 10 bits,
0..1023 for 0..5 V), packet 35 the OI mode (0 off, 1 passive, 2 safe, 3 full), packets
39 to 42 the velocity and radius last requested with Drive and the right and left wheel
velocities last requested with Drive Direct (signed, mm/s and mm; Create OI
specification 2006, p. 21).
"""

from __future__ import annotations

from dataclasses import dataclass, field

# opcodes (Stop, 173, only in the Create 2's OI: it ends the OI, the robot back in off
# mode with no stream; Create 2 OI specification 2016)
START, BAUD, CONTROL, SAFE, FULL, STOP = 128, 129, 130, 131, 132, 173
DRIVE, DRIVE_DIRECT = 137, 145
SENSORS, STREAM, QUERY_LIST, PAUSE_RESUME = 142, 148, 149, 150
STREAM_HEADER = 19
MAX_WHEEL_MM_S = 500

# packet id -> (data bytes, signed)
PACKETS: dict[int, tuple[int, bool]] = {
    7: (1, False),  # bumps and wheel drops
    19: (2, True),  # distance since last read, mm
    20: (2, True),  # angle since last read, degrees (Create)
    21: (1, False),  # charging state
    22: (2, False),  # battery voltage, mV
    25: (2, False),  # battery charge, mAh
    26: (2, False),  # battery capacity, mAh
    32: (1, False),  # cargo bay digital inputs (Create)
    33: (2, False),  # cargo bay analog signal, 10 bits (Create)
    35: (1, False),  # OI mode
    39: (2, True),  # requested velocity, mm/s, of the last Drive
    40: (2, True),  # requested radius, mm, of the last Drive
    41: (2, True),  # requested right wheel velocity, mm/s, of the last Drive Direct
    42: (2, True),  # requested left wheel velocity, mm/s, of the last Drive Direct
    43: (2, False),  # left encoder counts (Create 2), a wrapping 16-bit counter
    44: (2, False),  # right encoder counts (Create 2)
}

# What each model's bridge streams.
CREATE_STREAM = (7, 19, 20, 21, 22, 25, 26, 32, 33, 35, 41, 42)
CREATE2_STREAM = (7, 21, 22, 25, 26, 35, 43, 44)

# Baud codes of opcode 129 (OI specification table).
BAUD_CODES = {300: 0, 600: 1, 1200: 2, 2400: 3, 4800: 4, 9600: 5, 14400: 6, 19200: 7,
              28800: 8, 38400: 9, 57600: 10, 115200: 11}

# Data bytes after each opcode; None means "a count byte, then that many bytes".
COMMAND_ARGS: dict[int, int | None] = {
    START: 0, BAUD: 1, CONTROL: 0, SAFE: 0, FULL: 0, STOP: 0, DRIVE: 4, DRIVE_DIRECT: 4,
    SENSORS: 1, STREAM: None, QUERY_LIST: None, PAUSE_RESUME: 1,
}


class CodecError(ValueError):
    """A value that the protocol cannot carry."""


def _i16(value: int) -> bytes:
    if not -32768 <= value <= 32767:
        raise CodecError(f"{value} does not fit a signed 16-bit field")
    return (value & 0xFFFF).to_bytes(2, "big")


def checksum(body: bytes | bytearray) -> int:
    """The byte that makes ``sum(body) + it`` 0 modulo 256."""
    return (-sum(body)) & 0xFF


# host -> robot ---------------------------------------------------------------
def start() -> bytes:
    return bytes([START])


def safe() -> bytes:
    return bytes([SAFE])


def full() -> bytes:
    return bytes([FULL])


def stop() -> bytes:
    return bytes([STOP])


def baud(rate: int) -> bytes:
    if rate not in BAUD_CODES:
        raise CodecError(f"no baud code for {rate}")
    return bytes([BAUD, BAUD_CODES[rate]])


def clamp_wheel(mm_s: float) -> int:
    return int(max(-MAX_WHEEL_MM_S, min(MAX_WHEEL_MM_S, round(mm_s))))


def drive_direct(right_mm_s: float, left_mm_s: float) -> bytes:
    """Opcode 145: right wheel then left wheel, mm/s, each clamped to +-500."""
    return bytes([DRIVE_DIRECT]) + _i16(clamp_wheel(right_mm_s)) + _i16(clamp_wheel(left_mm_s))


def stream(ids: tuple[int, ...] | list[int]) -> bytes:
    for pid in ids:
        if pid not in PACKETS:
            raise CodecError(f"packet {pid} is not supported")
    return bytes([STREAM, len(ids), *ids])


def pause_resume(resume: bool) -> bytes:
    return bytes([PAUSE_RESUME, 1 if resume else 0])


def sensors(pid: int) -> bytes:
    return bytes([SENSORS, pid])


def query_list(ids: tuple[int, ...] | list[int]) -> bytes:
    return bytes([QUERY_LIST, len(ids), *ids])


# packet values ---------------------------------------------------------------
def encode_packet(pid: int, value: int) -> bytes:
    size, signed = PACKETS[pid]
    if size == 1:
        if not 0 <= value <= 255:
            raise CodecError(f"packet {pid}: {value} does not fit one byte")
        return bytes([value])
    if signed:
        return _i16(value)
    if not 0 <= value <= 0xFFFF:
        raise CodecError(f"packet {pid}: {value} does not fit 16 bits")
    return value.to_bytes(2, "big")


def decode_packet(pid: int, data: bytes) -> int:
    size, signed = PACKETS[pid]
    if len(data) != size:
        raise CodecError(f"packet {pid}: {len(data)} bytes, expected {size}")
    return int.from_bytes(data, "big", signed=signed)


def frame_length(ids: tuple[int, ...] | list[int]) -> int:
    """The byte count n of a stream frame of these packets."""
    return sum(1 + PACKETS[pid][0] for pid in ids)


# robot -> host ---------------------------------------------------------------
def encode_stream_frame(ids: tuple[int, ...] | list[int], values: dict[int, int]) -> bytes:
    """One stream frame (device side): 19, n, (id, data)..., checksum."""
    body = bytearray([STREAM_HEADER, frame_length(ids)])
    for pid in ids:
        body.append(pid)
        body += encode_packet(pid, values[pid])
    return bytes(body) + bytes([checksum(body)])


@dataclass
class StreamStats:
    frames: int = 0
    bad_checksum: int = 0
    bad_length: int = 0  # a header whose count or packet ids do not match the stream
    skipped_bytes: int = 0  # bytes thrown away while looking for a header

    @property
    def errors(self) -> int:
        return self.bad_checksum + self.bad_length


@dataclass
class StreamParser:
    """Incremental parser of the sensor stream for a known packet list.

    ``feed`` takes whatever bytes arrived and returns the frames completed, each as
    {packet id: value}. A header whose count, ids or checksum is wrong is dropped
    (counted) and the search restarts one byte later, so the parser finds the next
    real frame after garbage, truncation or a corrupt byte.
    """

    ids: tuple[int, ...]
    stats: StreamStats = field(default_factory=StreamStats)
    _buf: bytearray = field(default_factory=bytearray)

    def __post_init__(self) -> None:
        self.ids = tuple(self.ids)
        self._n = frame_length(self.ids)

    def reset(self) -> None:
        """Forget a partial frame (the port was reopened)."""
        self._buf.clear()

    def feed(self, data: bytes) -> list[dict[int, int]]:
        buf = self._buf
        buf += data
        out: list[dict[int, int]] = []
        total = self._n + 3
        while True:
            i = buf.find(STREAM_HEADER)
            if i < 0:
                self.stats.skipped_bytes += len(buf)
                buf.clear()
                break
            if i:
                self.stats.skipped_bytes += i
                del buf[:i]
            if len(buf) < 2:
                break
            if buf[1] != self._n:
                self.stats.bad_length += 1
                del buf[:1]
                continue
            if len(buf) < total:
                break
            frame = bytes(buf[:total])
            if sum(frame) & 0xFF:
                self.stats.bad_checksum += 1
                del buf[:1]
                continue
            values = self._unpack(frame[2:-1])
            if values is None:
                self.stats.bad_length += 1
                del buf[:1]
                continue
            del buf[:total]
            self.stats.frames += 1
            out.append(values)
        return out

    def _unpack(self, body: bytes) -> dict[int, int] | None:
        values: dict[int, int] = {}
        pos = 0
        for pid in self.ids:
            if body[pos] != pid:
                return None
            size = PACKETS[pid][0]
            values[pid] = decode_packet(pid, body[pos + 1 : pos + 1 + size])
            pos += 1 + size
        return values


# device side: the robot's command parser ------------------------------------
@dataclass
class CommandParser:
    """Incremental parser of host commands, for the emulated robot.

    Returns (opcode, data bytes) per complete command; an unknown opcode byte is
    counted and skipped (the robot would ignore it)."""

    unknown: int = 0
    _buf: bytearray = field(default_factory=bytearray)

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        buf = self._buf
        buf += data
        out: list[tuple[int, bytes]] = []
        while buf:
            op = buf[0]
            if op not in COMMAND_ARGS:
                self.unknown += 1
                del buf[:1]
                continue
            nargs = COMMAND_ARGS[op]
            if nargs is None:
                if len(buf) < 2:
                    break
                nargs = 1 + buf[1]
            if len(buf) < 1 + nargs:
                break
            out.append((op, bytes(buf[1 : 1 + nargs])))
            del buf[: 1 + nargs]
        return out


def parse_drive_direct(data: bytes) -> tuple[int, int]:
    """(right, left) mm/s from the 4 data bytes of opcode 145."""
    right = int.from_bytes(data[0:2], "big", signed=True)
    left = int.from_bytes(data[2:4], "big", signed=True)
    return right, left


def parse_id_list(data: bytes) -> tuple[int, ...]:
    """The packet ids of a Stream or Query List command's data (count, ids)."""
    return tuple(data[1 : 1 + data[0]])
