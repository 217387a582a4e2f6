"""Create readings in SI units, odometry, the upward ice sensor, wheel commands and the
command watchdog. Pure: the caller passes every time stamp.

Odometry (HARDWARE_NOTES, checked against the OI specifications and users' reports):
the original Create reports distance (packet 19, mm, mean of both wheels) and angle
(packet 20, degrees, counter-clockwise positive) since the previous read; the Create 2's
angle packet is known to be wrong, so there we use the wheel encoder counts
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


class Odometry:
    """Distance and heading change accumulated from stream frames until ``take``."""

    def __init__(self, spec: ModelSpec) -> None:
        self.spec = spec
        self._dist = 0.0
        self._dtheta = 0.0
        self._counts: tuple[int, int] | None = None

    def reset(self) -> None:
        """Forget the encoder reference (after a reconnect the counters moved unseen)."""
        self._counts = None

    def update(self, values: dict[int, int]) -> None:
        if self.spec.odometry == "packets":
            self._dist += values[19] / 1000.0
            self._dtheta += math.radians(values[20])
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
