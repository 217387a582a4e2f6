"""Create readings in SI units, odometry, the upward ice sensor, wheel commands and the
command watchdog. Pure: the caller passes every time stamp.

Odometry (HARDWARE_NOTES, checked against the OI specifications and users' reports):
the original Create reports distance (packet 19, mm, mean of both wheels) and angle
(packet 20, degrees, counter-clockwise positive) since the previous read, in whole units,
and older firmware drops the rest at every read, so that read every 15 ms they miss
anything slower than 1 unit a frame (``PacketOdometry`` says what we do about it); the
Create 2's angle packet is known to be wrong, so there we use the wheel encoder counts
(packets 43, 44: 16-bit counters that wrap), 508.8 counts per revolution of a 72 mm
wheel, wheel base 235 mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hwbridge.create import codec

COUNTS_PER_REV = 508.8
WHEEL_DIAMETER_M = 0.072
MM_PER_COUNT = math.pi * WHEEL_DIAMETER_M * 1000.0 / COUNTS_PER_REV
CREATE_WHEEL_BASE_M = 0.258  # original Create, HARDWARE_NOTES ("about 258 mm")
CREATE2_WHEEL_BASE_M = 0.235

MODES = {0: "off", 1: "passive", 2: "safe", 3: "full"}
STREAM_PERIOD_S = 0.015  # one stream frame every 15 ms (OI specifications, Stream)


@dataclass(frozen=True)
class ModelSpec:
    """What differs between the Create and the Create 2 for us."""

    name: str
    baud: int
    wheel_base_m: float
    stream_ids: tuple[int, ...]
    odometry: str  # "packets" (19/20) or "encoders" (43/44)
    cargo_bay: bool  # has the cargo bay analog and digital inputs
    oi_stop: bool = False  # its OI has Stop (173): the Create 2's; the original Create's not


MODELS = {
    "create": ModelSpec("create", 57600, CREATE_WHEEL_BASE_M, codec.CREATE_STREAM, "packets",
                        True),
    "create2": ModelSpec("create2", 115200, CREATE2_WHEEL_BASE_M, codec.CREATE2_STREAM,
                         "encoders", False, oi_stop=True),
}


@dataclass(frozen=True)
class Reading:
    """One stream frame in SI units."""

    bump_left: bool
    bump_right: bool
    wheel_drop: bool
    charging_state: int
    voltage_v: float
    charge_ah: float
    capacity_ah: float
    mode: str
    cargo_analog: int | None  # 0..1023, None on a Create 2
    cargo_digital: int | None  # bits of digital inputs 0..3


def reading_from(values: dict[int, int]) -> Reading:
    bumps = values.get(7, 0)
    return Reading(
        bump_right=bool(bumps & 0x01),
        bump_left=bool(bumps & 0x02),
        wheel_drop=bool(bumps & 0x1C),
        charging_state=values.get(21, 0),
        voltage_v=values.get(22, 0) / 1000.0,
        charge_ah=values.get(25, 0) / 1000.0,
        capacity_ah=values.get(26, 0) / 1000.0,
        mode=MODES.get(values.get(35, 0), "unknown"),
        cargo_analog=values.get(33),
        cargo_digital=values.get(32),
    )


def wrap_counts(new: int, old: int) -> int:
    """Signed change of a 16-bit counter that wraps (either direction)."""
    return ((new - old + 0x8000) & 0xFFFF) - 0x8000


def _within_a_unit(estimate: float, reported: int) -> float:
    return min(reported + 1.0, max(reported - 1.0, estimate))


class PacketOdometry:
    """One frame's motion of an original Create, from packets 19 and 20 and the wheel
    velocities it was asked for (packets 41 and 42).

    The original Create has no encoder packets (43/44 are the Create 2's), and its distance
    and angle come in whole mm and degrees; its firmware may drop the remainder at every
    read (a user's reading of AutonomyLab create_robot issue 28; the "older than 3.4.1" of
    libcreate issue 22 matches the Create 2's known bugs, Create 2 OI p. 41, and no manual
    settles it for the Create), so read every 15 ms a turn slower than about 67 deg/s, or a
    drive slower than 67 mm/s, would read as none. Reading less often only lowers that floor
    and still loses up to a unit a read. What we do instead: integrate the wheel velocities
    the robot reports as requested (mean of this frame's and the previous frame's, over the
    15 ms stream period) and keep the result within one unit of what the packets read.
    Whether the firmware keeps its remainder, drops it or rounds, a frame's true motion lies
    within one unit of its reading, so the bound never spoils a good estimate; and it keeps
    a bad one (wheels slipping or stalled against something: the request is not the motion)
    from straying further than the packets allow, which is why integrating the request
    alone, which libcreate's users tried, drifts. Where no wheel is asked to turn (the
    wheels stopped, passive or off mode, a wheel dropped) the robot moves only if pushed,
    and the packets are all we know: their readings are used as they are."""

    def __init__(self, wheel_base_m: float, period_s: float = STREAM_PERIOD_S) -> None:
        self.wheel_base_m = wheel_base_m
        self.period_s = period_s
        self._requested: tuple[int, int] | None = None

    def reset(self) -> None:
        self._requested = None

    def step(self, values: dict[int, int]) -> tuple[float, float]:
        """(distance m, heading change rad) of the frame ``values``."""
        dist_mm, angle_deg = values[19], values[20]
        driven = (MODES.get(values.get(35, 0)) in ("safe", "full")
                  and not values.get(7, 0) & 0x1C)
        now = (values[41], values[42]) if driven else (0, 0)
        before = self._requested if self._requested is not None else now
        self._requested = now
        right = 0.5 * (before[0] + now[0])  # mm/s over the frame's period
        left = 0.5 * (before[1] + now[1])
        if right == 0.0 and left == 0.0:
            return dist_mm / 1000.0, math.radians(angle_deg)
        model_mm = 0.5 * (right + left) * self.period_s
        model_deg = math.degrees((right - left) * self.period_s / (1000.0 * self.wheel_base_m))
        return (_within_a_unit(model_mm, dist_mm) / 1000.0,
                math.radians(_within_a_unit(model_deg, angle_deg)))


class Odometry:
    """Distance and heading change accumulated from stream frames until ``take``."""

    def __init__(self, spec: ModelSpec) -> None:
        self.spec = spec
        self._dist = 0.0
        self._dtheta = 0.0
        self._counts: tuple[int, int] | None = None
        self._packets = PacketOdometry(spec.wheel_base_m)

    def reset(self) -> None:
        """Forget the encoder reference (after a reconnect the counters moved unseen) and
        the wheel velocities last requested."""
        self._counts = None
        self._packets.reset()

    def update(self, values: dict[int, int]) -> None:
        if self.spec.odometry == "packets":
            dist, dtheta = self._packets.step(values)
            self._dist += dist
            self._dtheta += dtheta
            return
        left, right = values[43], values[44]
        if self._counts is not None:
            dl = wrap_counts(left, self._counts[0]) * MM_PER_COUNT / 1000.0
            dr = wrap_counts(right, self._counts[1]) * MM_PER_COUNT / 1000.0
            self._dist += 0.5 * (dl + dr)
            self._dtheta += (dr - dl) / self.spec.wheel_base_m
        self._counts = (left, right)

    def take(self) -> tuple[float, float]:
        """(distance m, heading change rad) since the previous ``take``."""
        out = (self._dist, self._dtheta)
        self._dist = self._dtheta = 0.0
        return out


@dataclass(frozen=True)
class IceSensor:
    """The upward infrared distance sensor on the cargo bay analog input (pin 4).

    Ice overhead is near, so the sensor's voltage is high: ice when the 10-bit value is
    at least ``threshold`` (calibrate it over ice and over open water; README)."""

    threshold: int = 512
    invert: bool = False

    def ice(self, analog: int | None) -> bool:
        if analog is None:
            return False
        return (analog >= self.threshold) != self.invert


def algae_from_digital(digital: int | None, bit: int = 0) -> bool:
    """The algae sensor's comparator output on cargo bay digital input ``bit``."""
    return bool(digital is not None and (digital >> bit) & 1)


def wheels_from_cmd(v: float, omega: float, wheel_base_m: float,
                    max_wheel_m_s: float = 0.5) -> tuple[int, int]:
    """(right, left) wheel speeds in mm/s for a (v, omega) command; both scaled down by
    the same factor if one would exceed the limit, so the path's curvature is kept."""
    half = 0.5 * omega * wheel_base_m
    right, left = v + half, v - half
    fastest = max(abs(right), abs(left))
    if fastest > max_wheel_m_s:
        scale = max_wheel_m_s / fastest
        right, left = right * scale, left * scale
    return codec.clamp_wheel(right * 1000.0), codec.clamp_wheel(left * 1000.0)


class Watchdog:
    """Expires when no command was fed for ``timeout_s``; the caller stops the wheels."""

    def __init__(self, timeout_s: float = 0.5) -> None:
        self.timeout_s = timeout_s
        self._last: float | None = None
        self.trips = 0
        self._tripped = True  # nothing commanded yet: wheels stay still

    def feed(self, now: float) -> None:
        self._last = now
        self._tripped = False

    def expired(self, now: float) -> bool:
        """True when the wheels must be stopped; counts each new trip once."""
        if self._last is None or now - self._last > self.timeout_s:
            if not self._tripped:
                self.trips += 1
                self._tripped = True
            return True
        return False
