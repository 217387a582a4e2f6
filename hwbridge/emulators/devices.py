"""The devices' side of the protocols, as pure state machines (no I/O, no clock).

``CreateDevice`` is an iRobot Create or Create 2 as the Open Interface describes it:
modes (off, passive, safe, full; drive commands are ignored unless safe or full; a
wheel drop in safe mode stops the wheels and falls back to passive), Drive Direct and
Drive, the sensor stream and single reads, odometry accumulated "since last read" with
the sub-unit remainder kept (or, with ``drop_remainder``, dropped at every read as the
original Create's firmware does), encoder counters that wrap. Its ``PowerPlan`` makes it as
hard to reach as a real one can be: asleep, switched on late, rebooting with the cable
in; ``babble`` makes it send noise and hear nothing (a robot at another baud rate, or a
noisy line). ``LmsDevice`` is a SICK LMS 2xx:
ACK or NAK for every telegram, mode and baud changes, the variant switch, measured values
on request or continuously; its replies can come late (``reply_latency_s``), as a real
one's do; its configuration (``config``: units, 8/16/32 m mode, real-time indices)
answers 0x74 and shapes every scan; ``fatal`` and ``partial_scans`` make its scans carry
a fatal status, or come as the passes of an interlaced scan. The pty shells in ``pty.py``
drive them.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from hwbridge.create import codec as oi
from hwbridge.create.model import MM_PER_COUNT, ModelSpec
from hwbridge.lms import codec as lms
from hwbridge.lms.model import ScanGeometry

MODE_NUMBERS = {"off": 0, "passive": 1, "safe": 2, "full": 3}

# What the emulated robot prints when it powers up: plain text, as a Create 2 prints its
# boot messages on the serial port at power-up (users' logs of the Roomba 600 firmware);
# to a stream parser it is garbage. Our own words.
BOOT_TEXT = b"\r\nemulated Create: power on\r\nfirmware: btrack emulator\r\nbattery ok\r\n"


@dataclass(frozen=True)
class PowerPlan:
    """When an emulated Create cannot hear the host, as a real one sometimes cannot.

    Times in seconds from the start of the run (what ``CreateDevice.advance`` is given).
    ``asleep_s``: asleep until then, deaf and silent (a Create 2 in passive mode goes to
    sleep after five minutes; Create 2 OI specification 2016, "Power Saving"), then awake
    in off mode. ``boot_s``: switched on only then: deaf and silent before, its boot text
    at power-up, then off mode. ``reboot_at_s``: reboots at these times with the cable in:
    the stream stops, the wheels stop, boot text, off mode, so it hears nothing but Start.
    """

    asleep_s: float = 0.0
    boot_s: float = 0.0
    reboot_at_s: tuple[float, ...] = ()

    @property
    def awake_at_s(self) -> float:
        return max(self.asleep_s, self.boot_s)


@dataclass
class CreateDevice:
    spec: ModelSpec
    mode: str = "off"
    right_mm_s: int = 0
    left_mm_s: int = 0
    stream_ids: tuple[int, ...] = ()
    streaming: bool = False
    baud: int = 0
    analog: int = 0  # cargo bay analog input, 0..1023
    digital: int = 0  # cargo bay digital inputs
    bumps: int = 0  # packet 7 bits
    voltage_mv: int = 16000
    charge_mah: int = 2500
    capacity_mah: int = 3000
    bad_commands: int = 0
    plan: PowerPlan = field(default_factory=PowerPlan)
    awake: bool = True  # False: asleep or switched off; it hears and sends nothing
    babble: bool = False  # noise instead of frames, and the host's bytes go unheard
    # Distance (19) and angle (20) keep only whole mm and degrees at each read and drop the
    # rest, as the original Create's firmware does: at one read per 15 ms stream period a
    # turn slower than 1 deg / 15 ms (about 67 deg/s) reads as none (AutonomyLab
    # create_robot issue 28; libcreate issue 22).
    drop_remainder: bool = False
    travelled_m: float = 0.0  # all the motion ever added, for tests to compare with
    turned_rad: float = 0.0
    unheard_bytes: int = 0  # host bytes that arrived while it could not hear them
    reboots: int = 0
    _parser: oi.CommandParser = field(default_factory=oi.CommandParser)
    _dist_mm: float = 0.0
    _angle_deg: float = 0.0
    _enc: list[float] = field(default_factory=lambda: [0.0, 0.0])
    _drive: tuple[int, int] = (0, 0)  # velocity and radius of the last Drive
    _t: float = 0.0
    _noise: random.Random = field(default_factory=lambda: random.Random(19))

    def __post_init__(self) -> None:
        self.baud = self.baud or self.spec.baud
        self.awake = self.plan.awake_at_s <= 0.0

    # power -----------------------------------------------------------------------
    def advance(self, t: float) -> bytes:
        """Apply the power plan up to run time ``t``; return what the robot sends of its own
        accord (boot text, noise while it babbles). Called once per stream period."""
        out = bytearray()
        if not self.awake and t >= self.plan.awake_at_s:
            self.awake = True
            self.mode = "off"
            if self.plan.boot_s > 0.0:
                out += BOOT_TEXT
        for at in self.plan.reboot_at_s:
            if self._t < at <= t:
                out += self.reboot()
        self._t = max(self._t, t)
        if self.babble and self.awake:
            out += bytes(self._noise.randrange(256) for _ in range(12))
        return bytes(out)

    def reboot(self) -> bytes:
        """Power cycled with the cable in: back in off mode with no stream; its boot text."""
        self.reboots += 1
        self.mode = "off"
        self.streaming = False
        self.stream_ids = ()
        self._stop()
        self._parser = oi.CommandParser()
        return BOOT_TEXT

    # commands from the host --------------------------------------------------
    def receive(self, data: bytes) -> bytes:
        """Apply the host's bytes; return what the robot answers at once."""
        if not self.awake or self.babble:
            self.unheard_bytes += len(data)
            return b""
        out = bytearray()
        for op, args in self._parser.feed(data):
            if op == oi.START:
                self.mode = "passive"
                self.streaming = False
                self._stop()
            elif self.mode == "off":
                self.bad_commands += 1  # the OI ignores everything before Start
            elif op == oi.STOP:
                if not self.spec.oi_stop:
                    self.bad_commands += 1  # not an opcode of this model's OI
                    continue
                self.mode = "off"
                self.streaming = False
                self._stop()
            elif op == oi.SAFE:
                self.mode = "safe"
            elif op == oi.FULL:
                self.mode = "full"
            elif op == oi.CONTROL:
                self.mode = "safe"
            elif op == oi.BAUD:
                rates = {code: rate for rate, code in oi.BAUD_CODES.items()}
                self.baud = rates.get(args[0], self.baud)
            elif op == oi.DRIVE_DIRECT:
                if self.mode in ("safe", "full"):
                    self.right_mm_s, self.left_mm_s = oi.parse_drive_direct(args)
            elif op == oi.DRIVE:
                if self.mode in ("safe", "full"):
                    self._drive_radius(args)
            elif op in (oi.STREAM, oi.QUERY_LIST, oi.SENSORS):
                ids = (args[0],) if op == oi.SENSORS else oi.parse_id_list(args)
                if any(pid not in oi.PACKETS for pid in ids):
                    self.bad_commands += 1
                    continue
                if op == oi.STREAM:
                    self.stream_ids, self.streaming = ids, bool(ids)
                else:
                    values = self.take_values(ids)
                    for pid in ids:
                        out += oi.encode_packet(pid, values[pid])
            elif op == oi.PAUSE_RESUME:
                self.streaming = bool(args[0]) and bool(self.stream_ids)
        self.bad_commands += self._parser.unknown
        self._parser.unknown = 0
        return bytes(out)

    def _stop(self) -> None:
        self.right_mm_s = self.left_mm_s = 0

    def _drive_radius(self, args: bytes) -> None:
        v = int.from_bytes(args[0:2], "big", signed=True)
        radius = int.from_bytes(args[2:4], "big", signed=True)
        self._drive = (v, radius)
        half_base = 500.0 * self.spec.wheel_base_m
        if radius in (-32768, 32767):
            r = left = v
        elif radius == 1:  # spin counter-clockwise
            r, left = v, -v
        elif radius == -1:
            r, left = -v, v
        else:
            r = int(v * (radius + half_base) / radius)
            left = int(v * (radius - half_base) / radius)
        self.right_mm_s, self.left_mm_s = oi.clamp_wheel(r), oi.clamp_wheel(left)

    # the world acting on the robot ---------------------------------------------
    def wheel_speeds(self) -> tuple[float, float]:
        """(right, left) m/s the motors actually turn at."""
        if self.mode not in ("safe", "full"):
            return 0.0, 0.0
        return self.right_mm_s / 1000.0, self.left_mm_s / 1000.0

    def add_motion(self, dist_m: float, dtheta: float) -> None:
        """What the wheel encoders measured over a physics step."""
        half = 0.5 * dtheta * self.spec.wheel_base_m
        self.travelled_m += dist_m
        self.turned_rad += dtheta
        self._dist_mm += dist_m * 1000.0
        self._angle_deg += math.degrees(dtheta)
        self._enc[0] += (dist_m - half) * 1000.0 / MM_PER_COUNT
        self._enc[1] += (dist_m + half) * 1000.0 / MM_PER_COUNT

    def roll(self, dt: float) -> None:
        """The robot on a floor: its wheels move it for ``dt`` seconds, exactly."""
        right, left = self.wheel_speeds()
        self.add_motion(0.5 * (right + left) * dt, (right - left) / self.spec.wheel_base_m * dt)

    def set_wheel_drop(self, dropped: bool) -> None:
        self.bumps = (self.bumps | 0x0C) if dropped else (self.bumps & ~0x1C)
        if dropped and self.mode == "safe":  # the OI's safety reaction
            self._stop()
            self.mode = "passive"

    # the robot's answers -------------------------------------------------------
    def take_values(self, ids: tuple[int, ...]) -> dict[int, int]:
        values: dict[int, int] = {}
        for pid in ids:
            if pid == 19:
                report = int(self._dist_mm)  # toward zero; the rest stays for next time
                self._dist_mm = 0.0 if self.drop_remainder else self._dist_mm - report
                values[pid] = max(-32768, min(32767, report))
            elif pid == 20:
                report = int(self._angle_deg)
                self._angle_deg = 0.0 if self.drop_remainder else self._angle_deg - report
                values[pid] = max(-32768, min(32767, report))
            elif pid in (43, 44):
                values[pid] = int(math.floor(self._enc[pid - 43])) & 0xFFFF
            else:
                values[pid] = {
                    7: self.bumps & 0x1F, 21: 0, 22: self.voltage_mv, 25: self.charge_mah,
                    26: self.capacity_mah, 32: self.digital & 0x1F, 33: self.analog & 0x3FF,
                    35: MODE_NUMBERS[self.mode], 39: self._drive[0], 40: self._drive[1],
                    41: self.right_mm_s, 42: self.left_mm_s,
                }[pid]
        return values

    def stream_frame(self) -> bytes | None:
        """The next stream frame, or None when not streaming."""
        if not self.streaming or not self.awake or self.babble:
            return None
        return oi.encode_stream_frame(self.stream_ids, self.take_values(self.stream_ids))


@dataclass(frozen=True)
class Reply:
    """Bytes the sensor sends ``delay_s`` after it heard a telegram; its line switches to
    ``baud_after`` once they are out (a baud change is answered at the old rate)."""

    delay_s: float
    data: bytes
    baud_after: int | None = None


@dataclass
class LmsDevice:
    geometry: ScanGeometry = field(default_factory=ScanGeometry)
    config: lms.LmsConfig = field(default_factory=lms.LmsConfig)
    baud: int = lms.POWER_UP_BAUD
    continuous: bool = False
    ranges_m: list[float] = field(default_factory=list)
    naks: int = 0
    # Seconds it takes to answer, by telegram: the key is the start of the payload
    # (command, data), the longest that matches wins; b"\x20" is every mode change. The
    # ACK comes at once. A real LMS can take up to about 3 s over a mode switch
    # (sicktoolbox, SickLMS2xx.hh: DEFAULT_SICK_LMS_2XX_SICK_SWITCH_MODE_TIMEOUT).
    reply_latency_s: dict[bytes, float] = field(default_factory=dict)
    scans_sent: int = 0  # its real-time scan and telegram indices, modulo 256 on the wire
    fatal: bool = False  # scans carry status "fatal error" (a fault in the sensor)
    nak_next: int = 0  # the next telegrams heard are NAKed, as if a glitch corrupted them
    partial_scans: bool = False  # scans come as partial scans, flag and index set
    _parser: lms.TelegramParser = field(
        default_factory=lambda: lms.TelegramParser(expect_reply=False))

    def _latency(self, payload: bytes) -> float:
        keys = [k for k in self.reply_latency_s if payload.startswith(k)]
        return self.reply_latency_s[max(keys, key=len)] if keys else 0.0

    def receive(self, data: bytes) -> list[Reply]:
        """Answer the host's bytes, in the order the answers go out."""
        out: list[Reply] = []
        before = self._parser.stats.bad_crc
        items = self._parser.feed(data)
        for _ in range(self._parser.stats.bad_crc - before):
            out.append(Reply(0.0, bytes([lms.NAK])))
            self.naks += 1
        for item in items:
            if not isinstance(item, lms.Telegram):
                continue
            if self.nak_next > 0:
                self.nak_next -= 1
                self.naks += 1
                out.append(Reply(0.0, bytes([lms.NAK])))
                continue
            out.append(Reply(0.0, bytes([lms.ACK])))
            cmd, args = item.command, item.data
            new_baud: int | None = None
            answer = bytearray()
            out_of = self._latency(bytes([cmd]) + args)
            if cmd == lms.MODE and args:
                mode = args[0]
                ok = mode in (lms.CONTINUOUS, lms.STOP_CONTINUOUS) or mode in lms.MODE_BAUDS
                if mode == lms.CONTINUOUS:
                    self.continuous = True
                elif mode == lms.STOP_CONTINUOUS:
                    self.continuous = False
                elif mode in lms.MODE_BAUDS:
                    new_baud = lms.MODE_BAUDS[mode]
                answer += lms.reply(lms.MODE, bytes([0x00 if ok else 0x01]))
            elif cmd == lms.REQUEST_VALUES:
                answer += self.values_telegram()
            elif cmd == lms.REQUEST_CONFIG:
                answer += lms.reply(lms.REQUEST_CONFIG, lms.encode_config(self.config))
            elif cmd == lms.VARIANT and len(args) == 4:
                angle = int.from_bytes(args[0:2], "little")
                res = int.from_bytes(args[2:4], "little")
                try:
                    self.geometry = ScanGeometry(angle, res, self.geometry.range_max_m)
                    switched = 1
                except ValueError:
                    switched = 0
                g = self.geometry
                answer += lms.reply(lms.VARIANT, bytes([switched])
                                    + g.angle_deg.to_bytes(2, "little")
                                    + g.resolution_centideg.to_bytes(2, "little"))
            else:
                answer += lms.reply(cmd, b"")  # acknowledged, nothing to report
            out.append(Reply(out_of, bytes(answer), new_baud))
        return out

    def values_telegram(self) -> bytes:
        n = self.geometry.beams
        ranges = (self.ranges_m + [math.inf] * n)[:n]
        self.scans_sent += 1
        raw = lms.ranges_to_values(ranges, self.config)
        partial = 0b100 | self.scans_sent % 4 if self.partial_scans else 0
        status = (0x10 & ~lms.STATUS_MASK) | lms.STATUS_FATAL if self.fatal else 0x10
        return lms.reply(lms.REQUEST_VALUES,
                         lms.encode_values(raw, self.config, self.scans_sent, partial,
                                           telegram_index=self.scans_sent),
                         status)
