"""The time stamps of a hardware run: wall-clock seconds since the run's epoch, and ticks.

Robot computers share only the wall clock (NTP), so every process of a run stamps
``t = wall - epoch`` with the same ``--epoch``; the value advances on the monotonic
clock (taken once against the wall clock at start), so a clock step mid-run cannot make
time run backwards. Ticks are counted from the epoch (k = t // dt) and fall on its grid,
so robots of one run share k as they do in simulation, where an agent waits for its
neighbours' states of tick k - 1. Only process shells use this; cores get ``t`` and ``dt``.
"""

from __future__ import annotations

import math
import time


class RunClock:
    def __init__(self, epoch: float | None = None) -> None:
        wall, mono = time.time(), time.monotonic()
        self.epoch = wall if epoch is None else epoch
        self._offset = (wall - self.epoch) - mono

    def t(self, mono: float | None = None) -> float:
        """Seconds since the epoch at monotonic time ``mono`` (now if None), never < 0."""
        m = time.monotonic() if mono is None else mono
        return max(0.0, m + self._offset)

    def mono_at(self, t: float) -> float:
        """The monotonic time at which the run clock reads ``t``."""
        return t - self._offset


def tick_of(t: float, dt: float) -> int:
    """The control tick at run time ``t``: every process of a run counts the same k."""
    return int(t // dt)


def tick_holding(t: float, dt: float) -> int:
    """The tick whose period ((k - 1) dt, k dt] holds a measurement taken at ``t`` (a
    laser scan): its sensing carries the odometry up to the measurement."""
    return max(0, math.ceil(t / dt - 1e-6))
